//! The STM32F405/F407 board (cargo feature `stm32f405`, MCU builds only),
//! on the `stm32f4` PAC: the period tick from SysTick, the link on USART1
//! (interrupt-driven both ways through two `heapless::spsc` queues), and
//! the `log` records on USART2 ([`crate::rt::serial_log`]).
//!
//! **One image for the board and for QEMU 7.2 `-M netduinoplus2`.**
//! - RCC: QEMU 7.2 does not model it (an unimplemented device that reads
//!   0) and runs the core at a fixed 168 MHz (the netduinoplus2 board's
//!   `sysclk`). [`setup_clocks`] reads RCC_CR first: 0 is impossible on a
//!   chip (HSION and HSIRDY are set out of reset), so it means "no RCC
//!   model" ([`ClockSource::NoRcc`], 168 MHz); on a chip it starts HSE 8 MHz
//!   → PLL 168 MHz with bounded waits, or stays on HSI 16 MHz.
//! - Why SysTick and not TIM2 paces the period: QEMU 7.2's TIM2..TIM5
//!   (`hw/timer/stm32f2xx_timer.c`, SoC `clock-frequency` 1 GHz, not a bus
//!   clock) cannot make a periodic update interrupt: `set_alarm` computes
//!   `hit_time` as an absolute virtual time and then arms the timer at
//!   `now + hit_time`, so every next update comes after the whole uptime
//!   again (the first one after ~the boot time, then ever later), and CNT
//!   reads a free-running 1 GHz/(PSC+1) count that never wraps at ARR.
//!   Measured here: a TIM2 calibrated at boot against SysTick read 465 to
//!   987 "MHz" and its update interrupt never paced anything. (A patch
//!   series rewriting the model on ptimer, with 48 MHz, was posted for
//!   later QEMU versions.) SysTick is modelled right in 7.2: on the
//!   processor clock it counts the board's 168 MHz, as on the chip, so
//!   reload = SYSCLK / 1000 − 1 gives 1 kHz on both with one image, at the
//!   highest exception priority. TIM2..TIM5 stay free for PWM (the motors).
//!
//! **Transmit: TXE interrupt, plus a bounded drain in [`Board::wait_tick`]
//! and [`Board::link_write`].** On the chip the TXE interrupt sends the
//! queue while the period logic runs (a 150-byte frame at 2 Mbaud takes
//! 750 µs, which a per-period drain could only do by spinning). QEMU 7.2's
//! USART (`hw/char/stm32f2xx_usart.c`) raises its interrupt only for RXNE
//! (CR1 TXEIE is stored but never raises it; later versions fixed that),
//! and every DR write is synchronous (TXE always reads set; the write
//! blocks the emulator until the host socket takes the byte). So the main
//! context also drains: with interrupts masked, while TXE is set, at most
//! [`DRAIN_BURST`] bytes. On the chip that loop stops after one or two
//! bytes (TXE clears while a character shifts out) and the interrupt does
//! the rest; under QEMU it sends the queue.

use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{scb::SystemHandler, NVIC, SCB, SYST};
use cortex_m_rt::exception;
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4::stm32f405::{self as pac, interrupt, Interrupt};
use tendril_shared::MAX_TENDONS;

use super::Board;

/// Receive queue, bytes (the spsc queue holds one byte less). At 2 Mbaud
/// it takes 2.5 ms of line time to fill; the node drains it every 1 ms
/// tick (the emulated link brings at most ~75 B per ms). A period may bring
/// a largest setpoint and a chunk together (≈ 420 B framed), so 512.
pub const RX_QUEUE: usize = 512;
/// Transmit queue, bytes: a period's command and telemetry (at most 84 and
/// 78 B before framing, kept under `MAX_UP_PAYLOAD` by a test) with
/// room to spare; at 2 Mbaud the line empties it in 1.3 ms. 256 rather than
/// 512 since nine tendons: the 256 B pay for the ninth tendon's arrays
/// inside the 32 KB RAM budget (a power of two: heapless's index
/// arithmetic stays masks, which 384 made divisions with a larger frame).
pub const TX_QUEUE: usize = 512;
/// Period tick rate, Hz.
pub const PERIOD_HZ: u32 = 1000;
/// Link baud rate on USART1 (PA9 TX, PA10 RX, AF7). The controller needs
/// ~150 B per 1 ms period each way: 1.5 Mbit/s of 10-bit characters at
/// least, so 2 Mbaud (PCLK2 84 MHz / 42; QEMU ignores BRR).
pub const LINK_BAUD: u32 = 2_000_000;
/// Log baud rate on USART2 (PA2 TX, AF7).
pub const LOG_BAUD: u32 = 115_200;
/// Bytes the USART1 interrupt moves per entry in each direction (bounds
/// its time: 32 bytes is a few µs of register accesses).
pub const ISR_BURST: usize = 32;

/// Bytes one main-context drain writes at most (see the module doc): under
/// QEMU a whole transmit queue; on the chip TXE stops it after ~2 bytes.
pub const DRAIN_BURST: usize = TX_QUEUE;

/// Iterations of a wait on an RCC ready bit before giving up. HSE start-up
/// is ≤ 2 ms on HSI (16 MHz: ~32 000 cycles; a poll iteration is a few
/// cycles); 400 000 allows 10× that, then the board runs on HSI.
const READY_SPINS: u32 = 400_000;

/// Where the core clock comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockSource {
    /// HSE 8 MHz → PLL 168 MHz (APB1 42 MHz, APB2 84 MHz): the board.
    Pll,
    /// The crystal or the PLL did not become ready in time: HSI 16 MHz,
    /// every bus at 16 MHz.
    Hsi,
    /// RCC reads as all zeros, which no real chip does (HSION and HSIRDY
    /// are set out of reset): an emulator without an RCC model (QEMU
    /// netduinoplus2), whose core runs at a fixed 168 MHz.
    NoRcc,
}

/// The clock tree the board ended up with.
#[derive(Clone, Copy, Debug)]
pub struct Clocks {
    /// Where SYSCLK comes from.
    pub source: ClockSource,
    /// Core clock (SysTick's processor clock), Hz.
    pub sysclk_hz: u32,
    /// APB1 clock (USART2), Hz.
    pub pclk1_hz: u32,
    /// APB2 clock (USART1), Hz.
    pub pclk2_hz: u32,
    /// SysTick reload value of the period (SysTick counts `reload + 1`
    /// core cycles per tick).
    pub reload: u32,
}

/// Link and tick counters since start.
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    /// Period ticks.
    pub ticks: u32,
    /// Ticks [`Board::wait_tick`] reported as missed, summed.
    pub missed: u32,
    /// Bytes received into the receive queue.
    pub rx_bytes: u32,
    /// Received bytes lost: USART overrun (ORE) or a full receive queue.
    pub rx_overruns: u32,
    /// Bytes written to the transmit register.
    pub tx_bytes: u32,
}

static TICKS: AtomicU32 = AtomicU32::new(0);
static RX_BYTES: AtomicU32 = AtomicU32::new(0);
static RX_OVERRUNS: AtomicU32 = AtomicU32::new(0);
static TX_BYTES: AtomicU32 = AtomicU32::new(0);

/// The queues' storage; split once in [`Stm32f405::take`].
static mut RX_Q: Queue<u8, RX_QUEUE> = Queue::new();
static mut TX_Q: Queue<u8, TX_QUEUE> = Queue::new();
/// The interrupt's ends of the queues: written once before USART1's
/// interrupt is unmasked, then touched only by that interrupt.
static mut RX_IN: Option<Producer<'static, u8>> = None;
/// The main context also uses `TX_OUT`, inside critical sections only
/// ([`drain_tx`]).
static mut TX_OUT: Option<Consumer<'static, u8>> = None;

/// Send queued bytes while TXE is set, at most `budget`, with interrupts
/// masked (exclusive use of the queue's consumer end and of DR).
fn drain_tx(budget: usize) {
    cortex_m::interrupt::free(|_| {
        // SAFETY: interrupts are masked, so the USART1 handler (the other
        // user of TX_OUT and DR) cannot run.
        let (usart, tx_out) = unsafe { (&*pac::USART1::ptr(), &mut *addr_of_mut!(TX_OUT)) };
        for _ in 0..budget {
            if usart.sr().read().txe().bit_is_clear() {
                break;
            }
            match tx_out.as_mut().and_then(|q| q.dequeue()) {
                Some(b) => {
                    usart.dr().write(|w| w.dr().set(u16::from(b)));
                    TX_BYTES.fetch_add(1, Ordering::Relaxed);
                }
                None => break,
            }
        }
    });
}

/// The STM32F405 board: owns the device peripherals it drives and the
/// main-context ends of the link queues.
pub struct Stm32f405 {
    clocks: Clocks,
    rx: Consumer<'static, u8>,
    tx: Producer<'static, u8>,
    last_tick: u32,
    missed: u32,
    period_ns: u64,
    tensions: [f32; MAX_TENDONS],
}

/// Spin until `ready()` or [`READY_SPINS`] polls; whether it became ready.
fn wait_for(mut ready: impl FnMut() -> bool) -> bool {
    (0..READY_SPINS).any(|_| ready())
}

/// HSE 8 MHz → PLL (M 8, N 336, P 2, Q 7) → 168 MHz; AHB 1, APB1 4, APB2 2;
/// flash 5 wait states (RM0090 Table 10, 2.7–3.6 V). Every wait on a ready
/// bit is bounded; on a timeout the chip stays on HSI.
fn setup_clocks(rcc: &pac::RCC, flash: &pac::FLASH) -> (ClockSource, u32, u32, u32) {
    const HSI: (u32, u32, u32) = (16_000_000, 16_000_000, 16_000_000);
    if rcc.cr().read().bits() == 0 {
        return (ClockSource::NoRcc, 168_000_000, 42_000_000, 84_000_000);
    }
    let on_hsi = || (ClockSource::Hsi, HSI.0, HSI.1, HSI.2);
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    if !wait_for(|| rcc.cr().read().hserdy().bit_is_set()) {
        rcc.cr().modify(|_, w| w.hseon().clear_bit());
        return on_hsi();
    }
    flash.acr().modify(|_, w| {
        w.latency().ws5();
        w.prften().set_bit();
        w.icen().set_bit();
        w.dcen().set_bit()
    });
    // SAFETY: M 8, N 336, Q 7 are inside the ranges RM0090 §7.3.2 allows
    // (M 2..=63, N 50..=432, Q 2..=15): VCO in 1 MHz, out 336 MHz.
    rcc.pllcfgr().modify(|_, w| unsafe {
        w.pllsrc().hse();
        w.pllm().bits(8);
        w.plln().bits(336);
        w.pllp().div2();
        w.pllq().bits(7)
    });
    rcc.cfgr().modify(|_, w| {
        w.hpre().div1();
        w.ppre1().div4();
        w.ppre2().div2()
    });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    if !wait_for(|| rcc.cr().read().pllrdy().bit_is_set()) {
        rcc.cfgr().modify(|_, w| {
            w.ppre1().div1();
            w.ppre2().div1()
        });
        return on_hsi();
    }
    rcc.cfgr().modify(|_, w| w.sw().pll());
    if !wait_for(|| rcc.cfgr().read().sws().is_pll()) {
        rcc.cfgr().modify(|_, w| {
            w.sw().hsi();
            w.ppre1().div1();
            w.ppre2().div1()
        });
        return on_hsi();
    }
    (ClockSource::Pll, 168_000_000, 42_000_000, 84_000_000)
}

impl Stm32f405 {
    /// Bring the board up: clocks, GPIO, the log UART (and the `log`
    /// logger on it), the link UART, then SysTick ticking at
    /// [`PERIOD_HZ`]. `None` if the peripherals were already taken. Takes
    /// the clock start-up (≤ a few ms on a chip, nothing under QEMU).
    pub fn take() -> Option<Self> {
        let dp = pac::Peripherals::take()?;
        let mut cp = cortex_m::Peripherals::take()?;
        let (source, sysclk_hz, pclk1_hz, pclk2_hz) = setup_clocks(&dp.RCC, &dp.FLASH);

        dp.RCC.ahb1enr().modify(|_, w| w.gpioaen().set_bit());
        dp.RCC.apb1enr().modify(|_, w| w.usart2en().set_bit());
        dp.RCC.apb2enr().modify(|_, w| w.usart1en().set_bit());
        // PA2/PA3 (USART2) and PA9/PA10 (USART1): alternate function 7;
        // pull-ups on the RX pins so an unconnected line reads idle.
        // (Named field accessors: the indexed ones bounds-check, a panic
        // path.)
        dp.GPIOA.moder().modify(|_, w| {
            w.moder2().alternate();
            w.moder3().alternate();
            w.moder9().alternate();
            w.moder10().alternate()
        });
        dp.GPIOA.afrl().modify(|_, w| w.afrl2().af7().afrl3().af7());
        dp.GPIOA
            .afrh()
            .modify(|_, w| w.afrh9().af7().afrh10().af7());
        dp.GPIOA
            .pupdr()
            .modify(|_, w| w.pupdr3().pull_up().pupdr10().pull_up());

        let brr =
            |pclk: u32, baud: u32| u16::try_from((pclk + baud / 2) / baud).unwrap_or(u16::MAX);
        dp.USART2
            .brr()
            // SAFETY: any 16-bit divider is a valid BRR (mantissa.fraction).
            .write(|w| unsafe { w.bits(brr(pclk1_hz, LOG_BAUD)) });
        dp.USART2.cr1().write(|w| w.ue().enabled().te().enabled());
        crate::rt::serial_log::init();

        // SAFETY: `take` succeeded, so this is the only split of the
        // queues; the interrupt's ends are stored before USART1's
        // interrupt is unmasked below and never touched here again.
        let (rx, tx) = unsafe {
            let (rx_in, rx_out) = (*addr_of_mut!(RX_Q)).split();
            let (tx_in, tx_out) = (*addr_of_mut!(TX_Q)).split();
            *addr_of_mut!(RX_IN) = Some(rx_in);
            *addr_of_mut!(TX_OUT) = Some(tx_out);
            (rx_out, tx_in)
        };
        dp.USART1
            .brr()
            // SAFETY: as for USART2.
            .write(|w| unsafe { w.bits(brr(pclk2_hz, LINK_BAUD)) });
        dp.USART1.cr1().write(|w| {
            w.ue().enabled();
            w.te().enabled();
            w.re().enabled();
            w.rxneie().enabled()
        });

        let reload = sysclk_hz / PERIOD_HZ - 1;
        let syst = &mut cp.SYST;
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(reload);
        syst.clear_current();
        // SAFETY: priorities set before the tick and the link interrupt
        // start; their handlers only touch their own statics.
        unsafe {
            cp.SCB.set_priority(SystemHandler::SysTick, 0x00);
            cp.NVIC.set_priority(Interrupt::USART1, 0x40);
            NVIC::unmask(Interrupt::USART1);
        }
        syst.enable_interrupt();
        syst.enable_counter();
        let clocks = Clocks {
            source,
            sysclk_hz,
            pclk1_hz,
            pclk2_hz,
            reload,
        };
        log::info!(
            "board stm32f405 clock {:?} sysclk {} systick reload {}",
            source,
            sysclk_hz,
            reload
        );
        Some(Self {
            clocks,
            rx,
            tx,
            last_tick: TICKS.load(Ordering::Relaxed),
            missed: 0,
            period_ns: 1_000_000_000 / u64::from(PERIOD_HZ),
            tensions: [0.0; MAX_TENDONS],
        })
    }

    /// The clock tree found at start-up.
    pub fn clocks(&self) -> Clocks {
        self.clocks
    }

    /// Tick and link counters since start.
    pub fn stats(&self) -> Stats {
        Stats {
            ticks: TICKS.load(Ordering::Relaxed),
            missed: self.missed,
            rx_bytes: RX_BYTES.load(Ordering::Relaxed),
            rx_overruns: RX_OVERRUNS.load(Ordering::Relaxed),
            tx_bytes: TX_BYTES.load(Ordering::Relaxed),
        }
    }

    /// The last tensions applied (this board has no motor outputs yet: PWM
    /// channels are the next step; the command is kept for inspection).
    pub fn tensions(&self) -> &[f32; MAX_TENDONS] {
        &self.tensions
    }
}

impl Board for Stm32f405 {
    fn link_overruns(&self) -> u32 {
        RX_OVERRUNS.load(Ordering::Relaxed)
    }

    fn wait_tick(&mut self) -> u32 {
        loop {
            drain_tx(DRAIN_BURST);
            // Check and sleep with interrupts masked: a tick that lands
            // between the check and the WFI still wakes the WFI (a pending
            // interrupt ends it even when masked), so no period is slept
            // through.
            cortex_m::interrupt::disable();
            let now = TICKS.load(Ordering::Relaxed);
            if now != self.last_tick {
                // SAFETY: re-enables what was enabled before this call.
                unsafe { cortex_m::interrupt::enable() };
                let missed = now.wrapping_sub(self.last_tick).wrapping_sub(1);
                self.last_tick = now;
                self.missed = self.missed.wrapping_add(missed);
                return missed;
            }
            cortex_m::asm::wfi();
            // SAFETY: as above; the pending interrupt runs now.
            unsafe { cortex_m::interrupt::enable() };
        }
    }

    fn now_ns(&self) -> u64 {
        let reload = self.clocks.reload;
        let (ticks, cvr) = cortex_m::interrupt::free(|_| {
            let ticks = TICKS.load(Ordering::Relaxed);
            let cvr = SYST::get_current();
            // A wrap not yet counted (its exception waits for this critical
            // section): read the counter again, after the wrap.
            if SCB::is_pendst_pending() {
                (ticks.wrapping_add(1), SYST::get_current())
            } else {
                (ticks, cvr)
            }
        });
        // SysTick counts down from `reload`.
        let into = u64::from(reload.saturating_sub(cvr));
        u64::from(ticks) * self.period_ns
            + into * 1_000_000_000 / u64::from(self.clocks.sysclk_hz.max(1))
    }

    fn set_tensions(&mut self, tensions: &[f32]) {
        for (slot, t) in self.tensions.iter_mut().zip(tensions) {
            *slot = *t;
        }
    }

    fn link_read(&mut self, buf: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in buf.iter_mut() {
            match self.rx.dequeue() {
                Some(b) => {
                    *slot = b;
                    n += 1;
                }
                None => break,
            }
        }
        if n > 0 {
            // Room again: let the receive interrupt run (it masks itself
            // when the queue is full).
            // SAFETY: unmasking the link interrupt, whose handler only
            // touches its own statics.
            unsafe { NVIC::unmask(Interrupt::USART1) };
        }
        n
    }

    fn link_write(&mut self, bytes: &[u8]) -> usize {
        let mut n = 0;
        for &b in bytes {
            if self.tx.enqueue(b).is_err() {
                break;
            }
            n += 1;
        }
        if n > 0 {
            // SAFETY: a read-modify-write of CR1 that the USART1 interrupt
            // also modifies (it clears TXEIE): done with interrupts masked.
            let usart = unsafe { &*pac::USART1::ptr() };
            cortex_m::interrupt::free(|_| usart.cr1().modify(|_, w| w.txeie().enabled()));
            drain_tx(DRAIN_BURST);
        }
        n
    }
}

/// The period tick: count it (the flag clears itself on exception entry).
#[exception]
fn SysTick() {
    TICKS.fetch_add(1, Ordering::Relaxed);
}

/// The link UART: received bytes into the receive queue (a full queue or
/// an ORE counts as an overrun), queued bytes out while TXE is set (TXEIE
/// is cleared when the queue runs empty). At most [`ISR_BURST`] bytes each
/// way per entry.
#[interrupt]
fn USART1() {
    // SAFETY: USART1 is this interrupt's; the queue ends were stored before
    // it was unmasked and only this handler uses them.
    let (usart, rx_in, tx_out) = unsafe {
        (
            &*pac::USART1::ptr(),
            &mut *addr_of_mut!(RX_IN),
            &mut *addr_of_mut!(TX_OUT),
        )
    };
    for _ in 0..ISR_BURST {
        // Queue full: stop taking bytes until `link_read` makes room, by
        // masking this interrupt (not RXNEIE: QEMU 7.2 lowers its USART
        // line only on a DR read, so a level left high would re-enter this
        // handler forever). The next byte then waits in DR: QEMU holds the
        // rest back (it offers a byte only while RXNE is clear), a chip
        // overruns (ORE, counted) if the period logic does not read in time.
        if !rx_in.as_ref().is_some_and(|q| q.ready()) {
            NVIC::mask(Interrupt::USART1);
            break;
        }
        let sr = usart.sr().read();
        if sr.rxne().bit_is_clear() && sr.ore().bit_is_clear() {
            break;
        }
        // Reading DR after SR clears RXNE and ORE.
        let byte = usart.dr().read().dr().bits() as u8;
        if sr.ore().bit_is_set() {
            RX_OVERRUNS.fetch_add(1, Ordering::Relaxed);
        }
        if sr.rxne().bit_is_set() {
            match rx_in.as_mut().map(|q| q.enqueue(byte)) {
                Some(Ok(())) => RX_BYTES.fetch_add(1, Ordering::Relaxed),
                _ => RX_OVERRUNS.fetch_add(1, Ordering::Relaxed),
            };
        }
    }
    if usart.cr1().read().txeie().is_enabled() {
        for _ in 0..ISR_BURST {
            if usart.sr().read().txe().bit_is_clear() {
                break;
            }
            match tx_out.as_mut().and_then(|q| q.dequeue()) {
                Some(b) => {
                    usart.dr().write(|w| w.dr().set(u16::from(b)));
                    TX_BYTES.fetch_add(1, Ordering::Relaxed);
                }
                None => {
                    usart.cr1().modify(|_, w| w.txeie().disabled());
                    break;
                }
            }
        }
    }
}
