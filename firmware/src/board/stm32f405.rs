//! The STM32F405/F407 board (cargo feature `stm32f405`, MCU builds only),
//! on the `stm32f4` PAC: the period tick from TIM2, the link on USART1
//! (interrupt-driven both ways through two `heapless::spsc` queues), and
//! the `log` records on USART2 ([`crate::rt::serial_log`]).
//!
//! **One image for the board and for QEMU `-M netduinoplus2`.** QEMU 7.2
//! does not model the RCC (an unimplemented device: reads 0), fixes the
//! core clock at 168 MHz (SysTick on the processor clock counts 168 MHz;
//! its reference clock is HCLK/8), and clocks TIM2..TIM5 at a fixed 48 MHz
//! (`stm32f405_soc.c` sets the timers' `clock-frequency` to 48 MHz) while
//! ignoring the prescaler (`stm32f2xx_timer.c`: a PSC write re-sets the
//! ptimer to the unscaled frequency) and masking ARR to 16 bits. A real
//! board clocks TIM2 at 2 × PCLK1 = 84 MHz. So [`Stm32f405::take`] does not
//! assume the timer clock: it runs TIM2 free with PSC = 0 for 5 ms of
//! SysTick (whose clock, the core clock, is known: 168 MHz from the PLL, or
//! 16 MHz on HSI if the crystal never started) and sets ARR from the rate
//! it measured, rounded to whole MHz (every STM32 timer clock is a whole
//! number of MHz; the rounding absorbs QEMU's host jitter during the 5 ms).
//! 1 kHz then needs ARR = 47 999 under QEMU and 83 999 on the board (TIM2
//! is 32-bit there; both fit).
//!
//! **Transmit is TXE-interrupt driven** (not a drain per period): the line
//! runs while the period logic runs, and a 150-byte frame at 2 Mbaud takes
//! 750 µs, which a per-period drain could only do by spinning. Under QEMU
//! every DR write is synchronous (TXE always reads set), so the interrupt
//! empties the queue at once, up to [`ISR_BURST`] bytes per entry.
//!
//! Interrupt priorities: TIM2 highest (the tick is never late behind link
//! bytes), USART1 below it.

use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::NVIC;
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4::stm32f405::{self as pac, interrupt, Interrupt};
use tendril_shared::MAX_TENDONS;

use super::Board;

/// Receive queue, bytes (the spsc queue holds one byte less). At 2 Mbaud
/// it takes 5 ms of line time to fill: five periods of slack.
pub const RX_QUEUE: usize = 1024;
/// Transmit queue, bytes: three periods' worth of ~150-byte frames.
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
    /// TIM2's counting rate as measured against SysTick at boot, Hz.
    pub timer_hz: u32,
    /// TIM2 auto-reload value of the period.
    pub arr: u32,
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
static mut TX_OUT: Option<Consumer<'static, u8>> = None;

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

/// TIM2's counting rate, Hz: TIM2 free-running (PSC 0, ARR 0xFFFF) timed
/// against SysTick on the core clock over 5 ms, rounded to whole MHz.
/// Bounded: the loop ends after 5 ms of SysTick or 10⁷ polls.
fn calibrate_timer(tim: &pac::TIM2, syst: &mut cortex_m::peripheral::SYST, sysclk_hz: u32) -> u32 {
    const MASK24: u32 = 0x00FF_FFFF;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(MASK24);
    syst.clear_current();
    syst.enable_counter();
    tim.psc().write(|w| w.psc().set(0));
    tim.arr().write(|w| w.arr().set(0xFFFF));
    tim.cnt().write(|w| w.cnt().set(0));
    tim.cr1().write(|w| w.cen().set_bit());
    let window = sysclk_hz / 200;
    let (mut s_prev, mut t_prev) = (
        cortex_m::peripheral::SYST::get_current(),
        tim.cnt().read().bits() & 0xFFFF,
    );
    let (mut s_sum, mut t_sum) = (0u32, 0u32);
    for _ in 0..10_000_000u32 {
        let s = cortex_m::peripheral::SYST::get_current();
        let t = tim.cnt().read().bits() & 0xFFFF;
        // SysTick counts down (24 bits), TIM2 up (16 bits used here); each
        // wraps far slower than one poll (≥ 0.78 ms).
        // A step "backwards" (QEMU's ptimer readout is not monotonic at
        // these rates) would read as almost a whole wrap: count it as 0;
        // a poll is far shorter than half a wrap, so no real step is lost.
        let ds = s_prev.wrapping_sub(s) & MASK24;
        let dt = t.wrapping_sub(t_prev) & 0xFFFF;
        s_sum = s_sum.wrapping_add(if ds < MASK24 / 2 { ds } else { 0 });
        t_sum = t_sum.wrapping_add(if dt < 0x8000 { dt } else { 0 });
        (s_prev, t_prev) = (s, t);
        if s_sum >= window {
            break;
        }
    }
    tim.cr1().write(|w| w.cen().clear_bit());
    syst.disable_counter();
    log::info!("calibration systick {s_sum} tim2 {t_sum}");
    let raw = (u64::from(t_sum) * u64::from(sysclk_hz))
        .checked_div(u64::from(s_sum))
        .unwrap_or(0);
    let mhz = (raw + 500_000) / 1_000_000;
    u32::try_from(mhz.saturating_mul(1_000_000))
        .unwrap_or(u32::MAX)
        .max(1_000_000)
}

impl Stm32f405 {
    /// Bring the board up: clocks, GPIO, the log UART (and the `log`
    /// logger on it), the link UART, then TIM2 calibrated and ticking at
    /// [`PERIOD_HZ`]. `None` if the peripherals were already taken. Takes
    /// about 5 ms (the timer calibration) plus the clock start-up.
    pub fn take() -> Option<Self> {
        let dp = pac::Peripherals::take()?;
        let mut cp = cortex_m::Peripherals::take()?;
        let (source, sysclk_hz, pclk1_hz, pclk2_hz) = setup_clocks(&dp.RCC, &dp.FLASH);

        dp.RCC.ahb1enr().modify(|_, w| w.gpioaen().set_bit());
        dp.RCC
            .apb1enr()
            .modify(|_, w| w.tim2en().set_bit().usart2en().set_bit());
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

        let timer_hz = calibrate_timer(&dp.TIM2, &mut cp.SYST, sysclk_hz);
        let arr = (timer_hz / PERIOD_HZ).saturating_sub(1);
        let tim = &dp.TIM2;
        tim.arr().write(|w| w.arr().set(arr));
        tim.cnt().write(|w| w.cnt().set(0));
        tim.sr().write(|w| w.uif().clear());
        tim.dier().write(|w| w.uie().set_bit());
        tim.cr1().write(|w| w.cen().set_bit());
        // SAFETY: priorities set before unmasking; the handlers below only
        // touch their own statics.
        unsafe {
            cp.NVIC.set_priority(Interrupt::TIM2, 0x00);
            cp.NVIC.set_priority(Interrupt::USART1, 0x40);
            NVIC::unpend(Interrupt::TIM2);
            NVIC::unmask(Interrupt::TIM2);
            NVIC::unmask(Interrupt::USART1);
        }
        let clocks = Clocks {
            source,
            sysclk_hz,
            pclk1_hz,
            pclk2_hz,
            timer_hz,
            arr,
        };
        log::info!(
            "board stm32f405 clock {:?} sysclk {} timer {} arr {}",
            source,
            sysclk_hz,
            timer_hz,
            arr
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
    fn wait_tick(&mut self) -> u32 {
        loop {
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
        // SAFETY: reads of TIM2's counter and status, which the TIM2
        // interrupt only clears (UIF).
        let tim = unsafe { &*pac::TIM2::ptr() };
        let (ticks, cnt) = cortex_m::interrupt::free(|_| {
            let ticks = TICKS.load(Ordering::Relaxed);
            let cnt = tim.cnt().read().bits();
            // A wrap not yet counted (its interrupt waits for this critical
            // section): read the counter again, after the wrap.
            if tim.sr().read().uif().bit_is_set() {
                (ticks.wrapping_add(1), tim.cnt().read().bits())
            } else {
                (ticks, cnt)
            }
        });
        u64::from(ticks) * self.period_ns
            + u64::from(cnt) * 1_000_000_000 / u64::from(self.clocks.timer_hz.max(1))
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
        }
        n
    }
}

/// The period tick: count it and clear the flag.
#[interrupt]
fn TIM2() {
    // SAFETY: TIM2's status register; the main context only reads it.
    let tim = unsafe { &*pac::TIM2::ptr() };
    if tim.sr().read().uif().bit_is_set() {
        tim.sr().write(|w| w.uif().clear());
        TICKS.fetch_add(1, Ordering::Relaxed);
    }
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
