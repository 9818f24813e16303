//! Host tests of the incremental hot swap (docs/design.md §5.3): sliced
//! checking gives exactly the one-shot answer, a blob that fails anywhere
//! leaves the old net running at every period, and a second blob mid-swap
//! supersedes the first.

use crate::test_support::*;

use core::task::Poll;
use std::boxed::Box;
use std::vec::Vec;

use proptest::prelude::*;
use tendril_shared::{weight_capacity, CascadeNet, CheckJob, TnetError};

use crate::infer::infer;
use crate::swap::{FlashSlot, IncrementalSwap, NetSlots, NetStore, SwapError, SwapEvent};
use crate::synth::synthetic_blob;

const W64: usize = weight_capacity(7, 64, 8);
type Net64 = CascadeNet<7, 64, 8, W64>;
type Slot<'a> = FlashSlot<'a, 7, 64, 8, W64>;
type Swap<'b> = IncrementalSwap<'b, 7, 64, 8, W64>;

fn blob(seed: u64, hidden: usize, outputs: usize) -> Vec<u8> {
    let mut buf = std::vec![0u8; 16384];
    let n = synthetic_blob(seed, hidden, outputs, 10.0, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// Run a [`CheckJob`] to its end with `budget` per slice; the answer and the
/// number of slices.
fn run_check(bytes: &[u8], budget: usize) -> (Result<tendril_shared::NetHeader, TnetError>, usize) {
    let mut job = CheckJob::<7, 64, 8, W64>::new(bytes);
    for slices in 1.. {
        if let Poll::Ready(r) = job.advance(budget) {
            // Finished is final: asking again gives the same answer.
            assert_eq!(
                job.advance(budget).map(|r| r.map(|c| *c.header())),
                Poll::Ready(r.map(|c| *c.header()))
            );
            return (r.map(|c| *c.header()), slices);
        }
        assert!(slices < 100_000, "check does not finish");
    }
    unreachable!()
}

/// Drive `swap` one slice per "period" until it is idle again, checking
/// before every slice that the running net is `old` (until the slice that
/// reports `Swapped`); returns the last event and the number of slices.
fn drive(
    swap: &mut Swap<'_>,
    store: &mut Slot<'_>,
    budget: usize,
    old: &Net64,
) -> (SwapEvent, usize) {
    let mut slices = 0;
    loop {
        assert_eq!(
            store.active(),
            old,
            "slice {slices}: the old net is not running"
        );
        slices += 1;
        match swap.slice(store, budget) {
            SwapEvent::Working => assert!(swap.busy()),
            SwapEvent::Idle => panic!("idle before the job ended"),
            done => {
                assert!(!swap.busy());
                return (done, slices);
            }
        }
    }
}

#[test]
fn sliced_check_gives_the_one_shot_answer_for_every_slice_size() {
    let good = blob(5, 64, 8);
    for budget in [0, 1, 4, 7, 64, 1000, 4096, 1 << 20] {
        let (r, slices) = run_check(&good, budget);
        assert_eq!(r, Net64::validate(&good), "budget {budget}");
        // Structure, hashing, six arrays, ranges: never fewer than 3 slices;
        // with a huge budget, one slice per stage and non-empty array.
        assert!(slices >= 3);
        if budget == 1 << 20 {
            assert_eq!(slices, 1 + 1 + 6 + 1);
        }
        // The body is hashed and scanned `budget` bytes (at least 4) at a time.
        let per = budget.max(4) & !3;
        assert!(
            slices <= 2 + good.len().div_ceil(per) + good.len().div_ceil(per) + 6,
            "budget {budget}: {slices}"
        );
    }
}

#[test]
fn slice_by_slice_swap_equals_the_one_shot_decode_flash_and_ram_running() {
    let flash = Net64::decode(&blob(3, 12, 8)).unwrap();
    let first = blob(8, 64, 8);
    let second = blob(9, 40, 8);
    for budget in [4, 333, 4096] {
        let mut ram = Box::new(Net64::empty());
        let mut store = Slot::new(&flash, &mut ram);
        let mut swap = Swap::new();
        assert_eq!(swap.slice(&mut store, budget), SwapEvent::Idle);
        // Flash running: the update goes to the RAM slot.
        swap.offer(&first, (7, 8)).unwrap();
        let (event, _) = drive(&mut swap, &mut store, budget, &flash);
        assert_eq!(event, SwapEvent::Swapped);
        assert!(store.running_ram());
        let want = Net64::decode(&first).unwrap();
        assert_eq!(store.active(), &want);
        // RAM running: the next update replaces it, the old one running
        // until the swap slice.
        swap.offer(&second, (7, 8)).unwrap();
        let (event, _) = drive(&mut swap, &mut store, budget, &want);
        assert_eq!(event, SwapEvent::Swapped);
        assert_eq!(store.active(), &Net64::decode(&second).unwrap());
        // Same as the one-shot path on a fresh store.
        let mut ram2 = Box::new(Net64::empty());
        let mut one_shot = Slot::new(&flash, &mut ram2);
        one_shot.load(&second, (7, 8)).unwrap();
        assert_eq!(store.active(), one_shot.active());
    }
}

#[test]
fn corruption_at_any_byte_leaves_the_old_net_at_every_period() {
    let flash = Net64::decode(&blob(3, 12, 8)).unwrap();
    let running = blob(8, 64, 8);
    let update = blob(9, 64, 8);
    let mut ram = Box::new(Net64::empty());
    let mut store = Slot::new(&flash, &mut ram);
    store.load(&running, (7, 8)).unwrap();
    let old = store.active().clone();
    let mut bad = update.clone();
    for i in 0..update.len() {
        bad[i] ^= 0x41;
        let mut swap = Swap::new();
        swap.offer(&bad, (7, 8)).unwrap();
        let (event, _) = drive(&mut swap, &mut store, 4096, &old);
        assert!(
            matches!(event, SwapEvent::Rejected(_)),
            "byte {i}: {event:?}"
        );
        // The one-shot path refuses it with the same error.
        let SwapEvent::Rejected(e) = event else {
            unreachable!()
        };
        assert_eq!(
            Err(e),
            NetStore::load(&mut NetSlots::<7, 64, 8, W64>::new(), &bad, (7, 8))
        );
        assert_eq!(store.active(), &old);
        assert!(store.running_ram());
        bad[i] = update[i];
    }
    // Truncated at every length, too (the running net stays).
    for n in 0..update.len() {
        let mut swap = Swap::new();
        swap.offer(&update[..n], (7, 8)).unwrap();
        let (event, _) = drive(&mut swap, &mut store, 4096, &old);
        assert!(
            matches!(event, SwapEvent::Rejected(SwapError::Decode(_))),
            "length {n}"
        );
    }
}

#[test]
fn a_valid_crc_over_a_nan_or_a_wrong_shape_is_refused_after_the_whole_check() {
    let flash = Net64::decode(&blob(3, 12, 8)).unwrap();
    let mut ram = Box::new(Net64::empty());
    let mut store = Slot::new(&flash, &mut ram);
    let mut nan = blob(9, 64, 8);
    let body = nan.len() - 4;
    nan[body - 4..body].copy_from_slice(&f32::NAN.to_le_bytes());
    let crc = tendril_shared::crc32::crc32(&nan[..body]);
    nan[body..].copy_from_slice(&crc.to_le_bytes());
    let mut swap = Swap::new();
    swap.offer(&nan, (7, 8)).unwrap();
    let (event, slices) = drive(&mut swap, &mut store, 4096, &flash);
    assert!(matches!(
        event,
        SwapEvent::Rejected(SwapError::Decode(TnetError::NonFinite { .. }))
    ));
    assert!(
        slices > 4,
        "the NaN is the last value: found only after hashing and scanning"
    );
    let four = blob(9, 64, 4);
    swap.offer(&four, (7, 8)).unwrap();
    let (event, _) = drive(&mut swap, &mut store, 4096, &flash);
    assert!(matches!(
        event,
        SwapEvent::Rejected(SwapError::ShapeMismatch { outputs: 4, .. })
    ));
    assert!(!store.running_ram());
}

#[test]
fn a_second_blob_mid_swap_supersedes_the_first() {
    let flash = Net64::decode(&blob(3, 12, 8)).unwrap();
    let first = blob(8, 64, 8);
    let second = blob(9, 64, 8);
    let mut ram = Box::new(Net64::empty());
    let mut store = Slot::new(&flash, &mut ram);
    let pose = [0.0, 0.0, 0.35, 0.95, 0.0, 0.0, 0.0];
    let mut swap = Swap::new();
    swap.offer(&first, (7, 8)).unwrap();
    for _ in 0..3 {
        assert_eq!(swap.slice(&mut store, 4096), SwapEvent::Working);
    }
    assert_eq!(swap.offer(&second, (7, 8)), Err(SwapError::Superseded));
    let (event, _) = drive(&mut swap, &mut store, 4096, &flash);
    assert_eq!(event, SwapEvent::Swapped);
    let want = Net64::decode(&second).unwrap();
    assert_eq!(store.active(), &want);
    assert_eq!(infer(store.active(), &pose), infer(&want, &pose));
    // Also when the first was already checked (its write was the next
    // slice): the second starts over, the first is never written.
    let mut ram = Box::new(Net64::empty());
    let mut store = Slot::new(&flash, &mut ram);
    let mut swap = Swap::new();
    swap.offer(&first, (7, 8)).unwrap();
    let mut n = 0;
    loop {
        let mut probe = swap;
        if probe.slice(&mut Slot::new(&flash, &mut Box::new(Net64::empty())), 4096)
            == SwapEvent::Swapped
        {
            break;
        }
        assert_eq!(swap.slice(&mut store, 4096), SwapEvent::Working);
        n += 1;
    }
    assert!(n > 3);
    assert_eq!(swap.offer(&second, (7, 8)), Err(SwapError::Superseded));
    // A bad second blob: both are gone, the old net runs on.
    let mut bad = second.clone();
    bad[100] ^= 1;
    assert_eq!(swap.offer(&bad, (7, 8)), Err(SwapError::Superseded));
    let (event, _) = drive(&mut swap, &mut store, 4096, &flash);
    assert!(matches!(
        event,
        SwapEvent::Rejected(SwapError::Decode(TnetError::CrcMismatch { .. }))
    ));
    assert!(!store.running_ram());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Any edit of a valid blob (a byte run overwritten, the CRC fixed or
    /// not, a cut) and any slice size: the sliced check answers exactly as
    /// the one-shot check.
    #[test]
    fn sliced_check_equals_one_shot_on_edited_blobs(
        seed in 0u64..1000,
        hidden in 0usize..=64,
        outputs in 1usize..=8,
        at in any::<prop::sample::Index>(),
        patch in prop::collection::vec(any::<u8>(), 0..12),
        fix_crc in any::<bool>(),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
        budget in 0usize..6000,
    ) {
        let mut b = blob(seed, hidden, outputs);
        let start = at.index(b.len());
        for (i, v) in patch.iter().enumerate() {
            if let Some(x) = b.get_mut(start + i) {
                *x = *v;
            }
        }
        if fix_crc && b.len() >= 4 {
            let n = b.len() - 4;
            let crc = tendril_shared::crc32::crc32(&b[..n]);
            b[n..].copy_from_slice(&crc.to_le_bytes());
        }
        if do_cut {
            b.truncate(cut.index(b.len() + 1));
        }
        let (r, _) = run_check(&b, budget);
        prop_assert_eq!(r, Net64::validate(&b));
    }
}

#[test]
fn a_rejected_blob_leaves_the_running_net_in_place() {
    let good = blob(3, 12, 4);
    let other = blob(8, 12, 4);
    let mut slots = NetSlots::<7, 16, 8, { weight_capacity(7, 16, 8) }>::new();
    slots.load(&good, (7, 4)).unwrap();
    let pose = mid_pose();
    let before = infer(slots.active(), &pose);
    let mut bad = other.clone();
    bad[30] ^= 1;
    assert!(matches!(
        slots.load(&bad, (7, 4)),
        Err(SwapError::Decode(_))
    ));
    assert_eq!(infer(slots.active(), &pose), before);
    assert!(matches!(
        slots.load(&blob(3, 12, 3), (7, 4)),
        Err(SwapError::ShapeMismatch { outputs: 3, .. })
    ));
    assert_eq!(infer(slots.active(), &pose), before);
    assert!(matches!(
        slots.load(&blob(3, 17, 4), (7, 4)),
        Err(SwapError::Decode(_))
    ));
    assert_eq!(infer(slots.active(), &pose), before);
    slots.load(&other, (7, 4)).unwrap();
    let after = infer(slots.active(), &pose);
    assert_eq!(after, infer(&Net::decode(&other).unwrap(), &pose));
    assert_ne!(after, before);
    // Swapping back and forth keeps working (both buffers reused).
    slots.load(&good, (7, 4)).unwrap();
    assert_eq!(infer(slots.active(), &pose), before);
}

/// `b` with its last weight (just before the CRC) NaN and the CRC
/// recomputed: passes every structural check, fails only on the value.
fn nan_blob(b: &[u8]) -> Vec<u8> {
    let mut bad = b.to_vec();
    let body = bad.len() - 4;
    bad[body - 4..body].copy_from_slice(&f32::NAN.to_le_bytes());
    let crc = tendril_shared::crc32::crc32(&bad[..body]);
    bad[body..].copy_from_slice(&crc.to_le_bytes());
    bad
}

#[test]
fn flash_slot_rejections_keep_the_running_net_flash_or_ram() {
    let flash = Net64::decode(&blob(3, 12, 4)).unwrap();
    let update = blob(8, 40, 4);
    let update2 = blob(9, 5, 4);
    let mut ram = std::boxed::Box::new(Net64::empty());
    let mut store = FlashSlot::new(&flash, &mut ram);
    let want = (7, 4);
    let mut crc_flip = update.clone();
    crc_flip[40] ^= 0x10;
    let rejects: [(&str, Vec<u8>); 5] = [
        ("NaN weight under a valid CRC", nan_blob(&update)),
        ("truncated", update[..update.len() - 1].to_vec()),
        ("corrupted byte", crc_flip),
        ("wrong output count", blob(8, 40, 3)),
        ("over capacity", blob(8, 65, 4)),
    ];
    let check_rejects = |store: &mut FlashSlot<'_, 7, 64, 8, { weight_capacity(7, 64, 8) }>,
                         running: &Net64,
                         on_ram: bool| {
        for (what, b) in &rejects {
            assert!(store.load(b, want).is_err(), "{what} accepted");
            assert_eq!(store.active(), running, "{what} changed the running net");
            assert_eq!(store.running_ram(), on_ram, "{what}");
        }
    };
    // The flash net runs; rejections leave it.
    check_rejects(&mut store, &flash, false);
    assert!(core::ptr::eq(store.active(), &flash));
    // An update goes to RAM and runs.
    let expected = Net64::decode(&update).unwrap();
    store.load(&update, want).unwrap();
    assert!(store.running_ram());
    assert_eq!(store.active(), &expected);
    // While the RAM slot runs, every rejection leaves it intact, including
    // the NaN blob that is only refused after the whole file was read.
    check_rejects(&mut store, &expected, true);
    // An update over the running RAM net; a smaller one leaves no stale weights.
    store.load(&update2, want).unwrap();
    assert_eq!(store.active(), &Net64::decode(&update2).unwrap());
    check_rejects(&mut store, &Net64::decode(&update2).unwrap(), true);
    // Back to flash.
    assert!(store.revert());
    assert!(!store.revert());
    assert!(core::ptr::eq(store.active(), &flash));
}

#[test]
fn the_flash_default_net_is_its_file_decoded_at_run_time() {
    // build.rs generated DEFAULT_NET from this file through `from_view` in
    // const context; the run-time decoder must give the same net.
    let file = include_bytes!(env!("TENDRIL_FW_NET_FILE"));
    let decoded = crate::McuNet::decode(file).unwrap();
    assert_eq!(crate::DEFAULT_NET, decoded);
    assert!(crate::DEFAULT_NET.shape().hidden <= tendril_shared::MAX_HIDDEN);
}
