//! The controller image's resource budgets (issue 25), measured:
//!
//! - **flash** of `tendril-fw-stm32` (the image a user flashes): vector
//!   table + `.text` + `.rodata` + `.data` (its initialiser is in flash),
//!   from the ELF's section headers, ≤ 96 KB;
//! - **RAM**: its static RAM (`.data` + `.bss` + `.uninit`) plus the stack,
//!   ≤ 32 KB, and with 2 KB of that to spare (issue 43). The stack is what
//!   the budget image `tendril-fw-budget` paints below its calls of
//!   `Node::tick` (the Setup's tick and every period's): the same node code
//!   (the same `Node::tick` frame in both images' disassembly), plus the
//!   STM32F405 image's `main` frame and its interrupt frames
//!   ([`MAIN_FRAME_BYTES`], [`INTERRUPT_BYTES`]);
//! - **instructions** of the worst period, one `Node::tick` that runs a
//!   period (its link bytes, the period, the command's encoding), under
//!   QEMU `mps2-an386 -icount shift=0` (the STM32 model has no usable
//!   cycle counter), ≤ 80,000, and with a tenth of that to spare.
//!
//! Every target has its own test and all of them are asserted (the
//! margins, and how they were won, are in BENCHMARKS.md, "Controller image
//! budgets (issue 25)"). Run with `--nocapture` for the numbers.
//!
//! Needs `qemu-system-arm` and the Rust target `thumbv7em-none-eabihf`;
//! without them every test FAILS with the line saying what to install.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use tendril::firmware_parity as parity;
use tendril_firmware::node::MCU_UPDATE_CAPACITY;
use tendril_firmware::period::event;
use tendril_tests::workspace_root;

/// Flash target of the controller image, bytes.
const FLASH_BUDGET: u64 = 96 * 1024;
/// Static RAM + stack target, bytes.
const RAM_BUDGET: u64 = 32 * 1024;
/// RAM the controller image must leave free under [`RAM_BUDGET`] (issue
/// 43: room for the controller to grow), bytes.
const RAM_HEADROOM: u64 = 2 * 1024;
/// Worst period target, instructions.
const PERIOD_BUDGET: u64 = 80_000;
/// Headroom the worst period must leave under [`PERIOD_BUDGET`]
/// (issue 43: room for the controller to grow), instructions.
const PERIOD_HEADROOM: u64 = PERIOD_BUDGET / 10;
/// Periods the budget image runs.
const PERIODS: usize = 400;

/// The STM32F405 image's stack above `Node::tick`: the cortex-m-rt
/// trampoline (`push {r7, lr}`, 8) and `main` (`push {r7, lr}; sub sp,
/// #0xb0`, 184), from `llvm-objdump -d` of the release image.
const MAIN_FRAME_BYTES: u64 = 8 + 184;
/// The STM32F405 board's interrupt frames on top of the deepest thread
/// stack, an estimate from the ARMv7-M exception model and the handlers'
/// disassembly: USART1 (priority 0x40) interrupts the node with the FPU in
/// use, so its frame is the extended one (26 words = 104 bytes, lazily
/// stacked but reserved) plus its `push {r4-r7, lr}` (20; it calls
/// nothing); SysTick (priority 0) can preempt it: a basic frame (8 words =
/// 32; the USART1 handler uses no FPU) plus `push {r7, lr}` (8). Each
/// frame may add 4 bytes of alignment: 8 more.
const INTERRUPT_BYTES: u64 = 104 + 20 + 32 + 8 + 8;

/// One line of the budget image: `period k instructions chunk slice stack`.
#[derive(Clone, Copy, Debug)]
#[allow(dead_code)]
struct Period {
    k: u32,
    instructions: u64,
    chunk: bool,
    slice: bool,
    stack: u64,
}

/// What the budget image printed.
#[derive(Debug)]
struct Budget {
    values: BTreeMap<String, u64>,
    periods: Vec<Period>,
}

impl Budget {
    fn get(&self, name: &str) -> u64 {
        *self
            .values
            .get(name)
            .unwrap_or_else(|| panic!("budget image printed no `budget {name}`"))
    }
}

fn parse_budget(out: &str) -> Budget {
    let mut values = BTreeMap::new();
    let mut periods = Vec::new();
    for line in out.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["budget", name, v] => {
                values.insert(name.to_string(), v.parse().expect("budget value"));
            }
            ["period", k, n, chunk, slice, stack] => periods.push(Period {
                k: k.parse().expect("period"),
                instructions: n.parse().expect("instructions"),
                chunk: *chunk == "1",
                slice: *slice == "1",
                stack: stack.parse().expect("stack"),
            }),
            _ => {}
        }
    }
    Budget { values, periods }
}

/// Build the budget image (as `firmware_parity` builds the MPS2 images, in
/// a target directory of its own) and run it once for all tests.
fn budget() -> &'static Budget {
    static RUN: OnceLock<Budget> = OnceLock::new();
    RUN.get_or_init(|| {
        parity::prerequisites().unwrap_or_else(|e| panic!("{e}"));
        let root = workspace_root();
        let dir = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join("target"))
            .join("thumbv7em-budget");
        let elf = parity::build_mcu_bin(&root, "tendril-fw-budget", None, None, &dir, "budget")
            .unwrap_or_else(|e| panic!("{e}"));
        let (ok, out) =
            parity::run_qemu(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        assert!(ok, "the budget image failed:\n{out}");
        assert!(
            out.contains("\ndone"),
            "the budget image did not finish:\n{out}"
        );
        parse_budget(&out)
    })
}

/// Section sizes of an ELF32 little-endian file, by name.
fn elf_sections(bytes: &[u8]) -> BTreeMap<String, u64> {
    let u16_at = |o: usize| u16::from_le_bytes(bytes[o..o + 2].try_into().unwrap());
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    assert_eq!(&bytes[..4], b"\x7fELF", "not an ELF file");
    assert_eq!(bytes[4], 1, "not ELF32");
    assert_eq!(bytes[5], 1, "not little-endian");
    let shoff = u32_at(0x20) as usize;
    let shentsize = usize::from(u16_at(0x2e));
    let shnum = usize::from(u16_at(0x30));
    let shstrndx = usize::from(u16_at(0x32));
    let header = |i: usize| shoff + i * shentsize;
    let strtab = u32_at(header(shstrndx) + 0x10) as usize;
    (0..shnum)
        .map(|i| {
            let h = header(i);
            let name_at = strtab + u32_at(h) as usize;
            let end = bytes[name_at..].iter().position(|&b| b == 0).unwrap();
            let name = String::from_utf8_lossy(&bytes[name_at..name_at + end]).into_owned();
            (name, u64::from(u32_at(h + 0x14)))
        })
        .collect()
}

/// The controller image's flash and static RAM, bytes.
#[derive(Clone, Copy, Debug)]
struct Sizes {
    flash: u64,
    static_ram: u64,
    data: u64,
    bss: u64,
}

fn chip_sizes() -> Sizes {
    static SIZES: OnceLock<Sizes> = OnceLock::new();
    *SIZES.get_or_init(|| {
        // Built as `tendril controller --mcu` builds it.
        let elf: PathBuf =
            tendril::mcu::build_image("tendril-fw-stm32").unwrap_or_else(|e| panic!("{e:#}"));
        sizes_of(&elf)
    })
}

fn sizes_of(elf: &Path) -> Sizes {
    let bytes = std::fs::read(elf).unwrap_or_else(|e| panic!("{}: {e}", elf.display()));
    let s = elf_sections(&bytes);
    let size = |name: &str| s.get(name).copied().unwrap_or(0);
    let data = size(".data");
    let bss = size(".bss");
    Sizes {
        flash: size(".vector_table") + size(".text") + size(".rodata") + data,
        static_ram: data + bss + size(".uninit"),
        data,
        bss,
    }
}

/// The controller image's stack: the node's (measured) + main + interrupts.
fn chip_stack() -> u64 {
    budget().get("node_stack_bytes") + MAIN_FRAME_BYTES + INTERRUPT_BYTES
}

/// The budget run is the run it claims: every period commanded, both
/// updates chunked and checked (one refused, one installed), no hold or
/// rejection cut a period short, and every period printed.
#[test]
fn budget_run_is_whole() {
    let b = budget();
    println!("budget image: {:#?}", b.values);
    assert_eq!(b.periods.len(), PERIODS);
    assert_eq!(b.get("periods"), PERIODS as u64);
    assert_eq!(b.get("commands"), PERIODS as u64);
    assert_eq!(b.get("bad_frames"), 0);
    assert_eq!(b.get("swapped"), 1, "the 7-64-4 update installs");
    assert_eq!(b.get("rejected"), 1, "the 7-64-8 update is refused");
    assert!(
        b.get("update_8_bytes") > 12_000 && b.get("update_8_bytes") <= MCU_UPDATE_CAPACITY as u64
    );
    assert!(b.get("chunk_periods") >= 100);
    assert!(b.get("swap_slice_periods") >= 6);
    assert!(b.periods.iter().any(|p| p.chunk) && b.periods.iter().any(|p| p.slice));
    let cut_short = event::OUTSIDE_WORKSPACE
        | event::WATCHDOG_HOLD
        | event::STUCK_MOTOR
        | event::PLANT_STALE
        | event::NONFINITE_SETPOINT
        | event::BAD_QUATERNION
        | event::SETPOINTS_LOST
        | event::COMMANDS_NOT_APPLIED;
    assert_eq!(
        b.get("events_seen") & u64::from(cut_short),
        0,
        "events {:#x}: some periods did not run the whole step",
        b.get("events_seen")
    );
    let worst = b.periods.iter().map(|p| p.instructions).max().unwrap();
    assert_eq!(worst, b.get("worst_period_instructions"));
    // The node's stack is the deepest of every tick measured, the Setup's
    // (it configures the period, in place) and the periods'.
    let deepest = b.periods.iter().map(|p| p.stack).max().unwrap();
    assert_eq!(
        b.get("node_stack_bytes"),
        deepest.max(b.get("setup_tick_stack_bytes"))
    );
    assert!(b.get("setup_tick_stack_bytes") > 0 && deepest > 0);
    // Instructions are measured, not zero (SysTick counted).
    assert!(b.get("p50_period_instructions") > 10_000);
}

/// The controller image's sizes are read from its ELF.
#[test]
fn chip_image_sizes_are_read() {
    let s = chip_sizes();
    let total = s.static_ram + chip_stack();
    println!(
        "tendril-fw-stm32: flash {} B, static RAM {} B (.data {}, .bss {}), stack {} B: \
         RAM {total} B, {} B free of {RAM_BUDGET}",
        s.flash,
        s.static_ram,
        s.data,
        s.bss,
        chip_stack(),
        RAM_BUDGET.saturating_sub(total)
    );
    // The node, with its update buffer, is in .data.
    assert!(s.data >= MCU_UPDATE_CAPACITY as u64, "{s:?}");
    assert!(s.flash > s.data && s.bss > 0, "{s:?}");
}

#[test]
fn flash_within_96_kb() {
    let s = chip_sizes();
    assert!(
        s.flash <= FLASH_BUDGET,
        "flash {} B > {FLASH_BUDGET} B",
        s.flash
    );
}

#[test]
fn static_ram_and_stack_within_32_kb() {
    let s = chip_sizes();
    let total = s.static_ram + chip_stack();
    assert!(
        total <= RAM_BUDGET,
        "static RAM {} B + stack {} B = {total} B > {RAM_BUDGET} B",
        s.static_ram,
        chip_stack()
    );
}

#[test]
fn static_ram_and_stack_leave_2_kb_of_the_budget() {
    let s = chip_sizes();
    let total = s.static_ram + chip_stack();
    assert!(
        total <= RAM_BUDGET - RAM_HEADROOM,
        "static RAM {} B + stack {} B = {total} B leaves {} B of the {RAM_BUDGET} B budget, \
         less than {RAM_HEADROOM} B",
        s.static_ram,
        chip_stack(),
        RAM_BUDGET.saturating_sub(total)
    );
}

#[test]
fn worst_period_within_80000_instructions() {
    let b = budget();
    let worst = b.get("worst_period_instructions");
    assert!(
        worst <= PERIOD_BUDGET,
        "worst period {worst} instructions > {PERIOD_BUDGET} (with a swap slice: {}, install: {})",
        b.get("worst_swap_slice_period_instructions"),
        b.get("install_period_instructions")
    );
}

#[test]
fn worst_period_leaves_a_tenth_of_the_budget() {
    let b = budget();
    let worst = b.get("worst_period_instructions");
    assert!(
        worst <= PERIOD_BUDGET - PERIOD_HEADROOM,
        "worst period {worst} instructions leaves less than {PERIOD_HEADROOM} of the \
         {PERIOD_BUDGET} budget (install period: {})",
        b.get("install_period_instructions")
    );
}
