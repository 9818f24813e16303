//! iceoryx2 glue: the `ZeroCopySend` wrapper for the `shared` messages, the
//! service names under a prefix, and one place that fixes every service's
//! quality-of-service settings (creator and openers must agree on them).

use std::fmt::Debug;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use tendril_shared::messages::{Control, PlantState, Setpoint, TensionCommand, WeightUpdate};

use super::IpcError;

/// The iceoryx2 service flavour: inter-process, shared memory.
pub type Svc = ipc::Service;

/// A process's iceoryx2 node (what owns its ports).
pub type IpcNode = Node<Svc>;

/// A `shared` message as an iceoryx2 payload. `shared` is `no_std` and knows
/// nothing of iceoryx2, and the orphan rule forbids implementing iceoryx2's
/// trait for its types here, hence the transparent wrapper.
#[repr(transparent)]
#[derive(Clone, Copy, Debug, Default)]
pub struct Wire<T>(pub T);

/// A message type that may cross process boundaries as plain bytes.
///
/// # Safety
/// Implement only for `#[repr(C)]` types made of numbers and arrays of
/// numbers (every bit pattern valid, no pointers); `NAME` must be unique.
pub unsafe trait Message: Copy + Debug + Default + 'static {
    /// Type name iceoryx2 compares when a port connects to a service.
    const NAME: &'static str;
}

// SAFETY: all five are #[repr(C)] structs of integers, floats and arrays
// thereof with explicit padding (layout tests in `shared::messages`).
unsafe impl Message for Setpoint {
    const NAME: &'static str = "tendril::Setpoint/v2";
}
unsafe impl Message for TensionCommand {
    const NAME: &'static str = "tendril::TensionCommand/v1";
}
unsafe impl Message for PlantState {
    const NAME: &'static str = "tendril::PlantState/v1";
}
unsafe impl Message for WeightUpdate {
    const NAME: &'static str = "tendril::WeightUpdate/v1";
}
unsafe impl Message for Control {
    const NAME: &'static str = "tendril::Control/v1";
}

// SAFETY: `Wire<T>` is `repr(transparent)` over a `Message`, whose contract is
// exactly ZeroCopySend's (self-contained, every bit pattern valid).
unsafe impl<T: Message> ZeroCopySend for Wire<T> {
    unsafe fn type_name() -> &'static str {
        T::NAME
    }
}

/// Remove the node entries that iceoryx2 cannot clean itself: a process
/// killed while creating its node leaves its details file (which names the
/// process) without the monitor token iceoryx2 uses to tell a dead node from
/// a live one, so no later node ever removes it. Only entries of the given
/// processes — a launcher's children, already reaped — are touched; returns
/// how many were removed.
pub fn remove_orphan_node_entries(dead_pids: &[u32]) -> usize {
    let (nodes, prefix) = node_directory();
    let Ok(entries) = std::fs::read_dir(&nodes) else {
        return 0;
    };
    let mut removed = 0;
    for entry in entries.flatten() {
        let dir = entry.path();
        let details = dir.join(format!("{prefix}node.details"));
        let Ok(text) = std::fs::read_to_string(&details) else {
            continue;
        };
        let pid = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("process = "))
            .and_then(|v| v.trim().parse::<u32>().ok());
        if pid.is_some_and(|p| dead_pids.contains(&p)) && std::fs::remove_dir_all(&dir).is_ok() {
            log::debug!("removed the orphaned iceoryx2 node entry {}", dir.display());
            removed += 1;
        }
    }
    removed
}

/// The directory where iceoryx2 keeps its node entries, and the prefix of
/// its file names there.
fn node_directory() -> (std::path::PathBuf, String) {
    let global = &iceoryx2::config::Config::global_config().global;
    let nodes = std::path::PathBuf::from(global.root_path().to_string())
        .join(global.node.directory.to_string());
    (nodes, global.prefix.to_string())
}

/// Names of the node entries (directories) iceoryx2 has now: a launcher
/// takes this before it starts its children, so that
/// [`remove_broken_node_entries`] touches only what appeared during its run.
pub fn node_entry_names() -> std::collections::HashSet<std::ffi::OsString> {
    let (nodes, _) = node_directory();
    std::fs::read_dir(nodes)
        .map(|d| {
            d.flatten()
                .filter(|e| e.path().is_dir())
                .map(|e| e.file_name())
                .collect()
        })
        .unwrap_or_default()
}

/// Whether any process holds a lock on `path` (iceoryx2's node monitor is a
/// file its node keeps locked for its whole life; the kernel drops the lock
/// when the process dies).
fn file_is_locked(path: &std::path::Path) -> bool {
    use std::os::fd::AsRawFd;
    let Ok(file) = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
    else {
        return false;
    };
    // SAFETY: a zeroed `flock` is a valid argument; F_GETLK only writes it.
    let mut query: libc::flock = unsafe { std::mem::zeroed() };
    query.l_type = libc::F_WRLCK as _;
    query.l_whence = libc::SEEK_SET as _;
    // SAFETY: `file` is open for the call; `query` lives across it.
    let rc = unsafe { libc::fcntl(file.as_raw_fd(), libc::F_GETLK, &mut query) };
    rc == 0 && i32::from(query.l_type) != libc::F_UNLCK
}

/// Remove the node entries a process killed while tearing its node down
/// leaves behind (docs/design.md §6): a node directory whose details file is
/// already gone — so neither iceoryx2's dead-node cleanup nor
/// [`remove_orphan_node_entries`] can tell whose it was — holding only
/// service tags, beside monitor files that no process holds locked any more.
/// Only entries that are not in `before` (those that appeared during this
/// launcher's run) are touched; returns how many were removed.
pub fn remove_broken_node_entries(before: &std::collections::HashSet<std::ffi::OsString>) -> usize {
    let (nodes, prefix) = node_directory();
    let details = format!("{prefix}node.details");
    let mut removed = 0;
    for name in node_entry_names() {
        if before.contains(&name) {
            continue;
        }
        let dir = nodes.join(&name);
        let id = name.to_string_lossy();
        let monitor = nodes.join(format!("{prefix}{id}.node_monitor"));
        if dir.join(&details).exists() || !monitor.exists() || file_is_locked(&monitor) {
            continue;
        }
        if std::fs::remove_dir_all(&dir).is_ok() {
            for suffix in ["", "_context", "_owner_lock"] {
                let _ =
                    std::fs::remove_file(nodes.join(format!("{prefix}{id}.node_monitor{suffix}")));
            }
            log::debug!("removed the broken iceoryx2 node entry {}", dir.display());
            removed += 1;
        }
    }
    removed
}

/// Held by a supervised child for as long as its node lives (declare it
/// right after the node, so it drops before it): when the child ends
/// because its launcher died (SIGKILL leaves the launcher no chance to clean
/// up), it removes the resources of the dead nodes — the launcher's own,
/// and a child's killed before — so that the run's services go with the
/// last child instead of waiting in `/dev/shm` for the next sim (issue 31).
pub struct ReleaseIfOrphaned<'a>(pub &'a Node<Svc>);

impl Drop for ReleaseIfOrphaned<'_> {
    fn drop(&mut self) {
        if super::launcher_gone() {
            let state = self
                .0
                .blocking_cleanup_dead_nodes(std::time::Duration::from_millis(500));
            log::info!(
                "launcher gone: removed {} dead iceoryx2 node(s) ({} could not be)",
                state.cleanups,
                state.failed_cleanups
            );
        }
    }
}

/// Publisher of one message type.
pub type Pub<T> = Publisher<Svc, Wire<T>, ()>;
/// Subscriber of one message type.
pub type Sub<T> = Subscriber<Svc, Wire<T>, ()>;
type Factory<T> = publish_subscribe::PortFactory<Svc, Wire<T>, ()>;

/// Default service-name prefix; tests and `tendril sim` use a unique one.
pub const DEFAULT_PREFIX: &str = "tendril";

/// The iceoryx2 services of one control loop, all under one prefix.
pub struct Services {
    /// planner → controller.
    pub setpoint: Factory<Setpoint>,
    /// controller → plant.
    pub tension_cmd: Factory<TensionCommand>,
    /// Event raised after each tension command so the plant can sleep until one arrives.
    pub tension_cmd_event: event::PortFactory<Svc>,
    /// plant → controller, planner.
    pub plant_state: Factory<PlantState>,
    /// anyone → controller: a new `.tnet`.
    pub weights: Factory<WeightUpdate>,
    /// launcher → everyone: stop.
    pub control: Factory<Control>,
}

fn service_name(prefix: &str, topic: &str) -> Result<ServiceName, IpcError> {
    let full = format!("{prefix}/{topic}");
    ServiceName::new(&full).map_err(|e| IpcError::BadName(format!("service name {full:?}: {e:?}")))
}

fn pubsub<T: Message>(
    node: &Node<Svc>,
    prefix: &str,
    topic: &str,
    buffer: usize,
    history: usize,
) -> Result<Factory<T>, IpcError> {
    let name = service_name(prefix, topic)?;
    node.service_builder(&name)
        .publish_subscribe::<Wire<T>>()
        // A restarted process gets a new publisher while the dead one's port
        // waits for cleanup: room for a few of each.
        .max_publishers(4)
        .max_subscribers(8)
        .max_nodes(16)
        .subscriber_max_buffer_size(buffer)
        .history_size(history)
        // Receivers want the newest message; on overflow drop the oldest.
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| IpcError::Service(format!("{}: {e:?}", name.as_str())))
}

/// How long a service another process is creating may stay "in creation"
/// before opening it is an error (s).
pub const CREATION_RACE_S: f64 = 2.0;

impl Services {
    /// Open the services under `prefix`, creating any that do not exist.
    /// Create them in a launcher *before* spawning peers: concurrent
    /// `open_or_create` calls racing a dead-node cleanup can fail.
    ///
    /// Processes started independently (by hand, or by a test) race each
    /// other's creation: a service another process is still creating is
    /// reported as "hangs in creation" / "being created by another
    /// instance". That is transient, so those errors are retried for up to
    /// [`CREATION_RACE_S`] before they count.
    pub fn open_or_create(node: &Node<Svc>, prefix: &str) -> Result<Services, IpcError> {
        let deadline =
            std::time::Instant::now() + std::time::Duration::from_secs_f64(CREATION_RACE_S);
        loop {
            match Self::open_or_create_once(node, prefix) {
                Err(IpcError::Service(why))
                    if (why.contains("HangsInCreation") || why.contains("IsBeingCreated"))
                        && std::time::Instant::now() < deadline =>
                {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                other => return other,
            }
        }
    }

    fn open_or_create_once(node: &Node<Svc>, prefix: &str) -> Result<Services, IpcError> {
        let event_name = service_name(prefix, "tension_cmd")?;
        let tension_cmd_event = node
            .service_builder(&event_name)
            .event()
            .max_notifiers(8)
            .max_listeners(8)
            .max_nodes(16)
            .open_or_create()
            .map_err(|e| IpcError::Service(format!("{} (event): {e:?}", event_name.as_str())))?;
        Ok(Services {
            setpoint: pubsub(node, prefix, "setpoint", 8, 1)?,
            tension_cmd: pubsub(node, prefix, "tension_cmd", 8, 1)?,
            tension_cmd_event,
            plant_state: pubsub(node, prefix, "plant_state", 8, 1)?,
            weights: pubsub(node, prefix, "weights", 2, 0)?,
            control: pubsub(node, prefix, "control", 4, 1)?,
        })
    }
}

/// Create this process's iceoryx2 node. Creating a node also removes the
/// resources of dead nodes (a crashed predecessor), which is how a restarted
/// process takes over a killed one's place.
pub fn node(name: &str) -> Result<Node<Svc>, IpcError> {
    // iceoryx2 logs to the console itself; keep it to errors (IOX2_LOG_LEVEL wins).
    set_log_level_from_env_or(LogLevel::Error);
    let node_name =
        NodeName::new(name).map_err(|e| IpcError::BadName(format!("node name {name:?}: {e:?}")))?;
    NodeBuilder::new()
        .name(&node_name)
        // The one signal mechanism is crate::interrupt's.
        .signal_handling_mode(iceoryx2::prelude::SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| IpcError::Service(format!("node {name}: {e:?}")))
}

/// Make a publisher for a service.
pub fn publisher<T: Message>(factory: &Factory<T>) -> Result<Pub<T>, IpcError> {
    factory
        .publisher_builder()
        .create()
        .map_err(|e| IpcError::Port(format!("publisher {}: {e:?}", T::NAME)))
}

/// Make a subscriber for a service.
pub fn subscriber<T: Message>(factory: &Factory<T>) -> Result<Sub<T>, IpcError> {
    factory
        .subscriber_builder()
        .create()
        .map_err(|e| IpcError::Port(format!("subscriber {}: {e:?}", T::NAME)))
}

/// Make a notifier for an event service.
pub fn notifier(factory: &event::PortFactory<Svc>) -> Result<Notifier<Svc>, IpcError> {
    factory
        .notifier_builder()
        .create()
        .map_err(|e| IpcError::Port(format!("notifier: {e:?}")))
}

/// Make a listener for an event service.
pub fn listener(factory: &event::PortFactory<Svc>) -> Result<Listener<Svc>, IpcError> {
    factory
        .listener_builder()
        .create()
        .map_err(|e| IpcError::Port(format!("listener: {e:?}")))
}

/// Publish one message (copied into a loaned shared-memory sample).
pub fn send<T: Message>(publisher: &Pub<T>, msg: T) -> Result<(), IpcError> {
    let sample = publisher
        .loan_uninit()
        .map_err(|e| IpcError::Send(format!("{}: {e:?}", T::NAME)))?;
    sample
        .write_payload(Wire(msg))
        .send()
        .map_err(|e| IpcError::Send(format!("{}: {e:?}", T::NAME)))?;
    Ok(())
}

/// Drain a subscriber and return the newest message and how many arrived.
pub fn latest<T: Message>(subscriber: &Sub<T>) -> Result<(Option<T>, usize), IpcError> {
    latest_inspecting(subscriber, |_| {})
}

/// [`latest`], calling `superseded` on every message a newer one replaced
/// (oldest first), so that a receiver which keeps only the newest can still
/// see what it dropped — a NaN setpoint must be counted even when the next
/// one arrived in the same period.
pub fn latest_inspecting<T: Message>(
    subscriber: &Sub<T>,
    mut superseded: impl FnMut(&T),
) -> Result<(Option<T>, usize), IpcError> {
    let mut newest: Option<T> = None;
    let mut count = 0;
    while let Some(sample) = subscriber
        .receive()
        .map_err(|e| IpcError::Receive(format!("{}: {e:?}", T::NAME)))?
    {
        if let Some(old) = newest.as_ref() {
            superseded(old);
        }
        newest = Some(sample.payload().0);
        count += 1;
    }
    Ok((newest, count))
}

/// Receive every pending message, oldest first, into `out`.
pub fn drain<T: Message>(subscriber: &Sub<T>, out: &mut Vec<T>) -> Result<(), IpcError> {
    while let Some(sample) = subscriber
        .receive()
        .map_err(|e| IpcError::Receive(format!("{}: {e:?}", T::NAME)))?
    {
        out.push(sample.payload().0);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tendril_shared::messages::Header;

    /// In iceoryx2's node directory: a fabricated broken entry (no details,
    /// monitor unlocked) that appeared after the snapshot is removed with its
    /// monitor files; a fabricated one that existed before the snapshot, and
    /// a real live node created after it, are kept.
    #[test]
    fn only_broken_node_entries_that_appeared_after_the_snapshot_are_removed() {
        let (nodes, prefix) = node_directory();
        std::fs::create_dir_all(&nodes).unwrap();
        let unique = format!("9{}", std::process::id());
        let monitor_files = |id: &str| {
            ["", "_context", "_owner_lock"]
                .map(|suffix| nodes.join(format!("{prefix}{id}.node_monitor{suffix}")))
        };
        let make = |id: &str| {
            let dir = nodes.join(id);
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(dir.join(format!("{prefix}0000.service_tag")), b"").unwrap();
            for f in monitor_files(id) {
                std::fs::write(f, b"").unwrap();
            }
            dir
        };
        let old_id = format!("{unique}1");
        let old = make(&old_id);
        let before = node_entry_names();
        let broken_id = format!("{unique}2");
        let broken = make(&broken_id);
        let _live = node("tendril-transport-test").unwrap();
        let live_dir = node_entry_names()
            .into_iter()
            .map(|name| nodes.join(name))
            .find(|dir| {
                std::fs::read_to_string(dir.join(format!("{prefix}node.details")))
                    .is_ok_and(|text| text.contains("tendril-transport-test"))
            });

        remove_broken_node_entries(&before);
        let broken_left = broken.exists() || monitor_files(&broken_id).iter().any(|f| f.exists());
        let old_kept = old.exists();
        let live_kept = live_dir.as_ref().map(|d| d.exists());
        let _ = std::fs::remove_dir_all(&old);
        for f in monitor_files(&old_id) {
            let _ = std::fs::remove_file(f);
        }
        assert!(!broken_left, "the broken entry or its monitor files stayed");
        assert!(old_kept, "an entry older than the snapshot was removed");
        assert_eq!(
            live_kept,
            Some(true),
            "a live node's entry was removed (or not found)"
        );
    }

    fn setpoint(seq: u64, x: f32) -> Setpoint {
        Setpoint {
            header: Header { seq, stamp_ns: 0 },
            pose: [x, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0],
            velocity: [0.0; 7],
            tangent: [[0.0; 7]; 3],
            tangent_axes: [[0.0; 3]; 3],
            tangent_dim: 0,
            flags: 0,
            dynamic_offset: [0.0; 3],
            reserved: 0,
        }
    }

    /// Two setpoints in one period, the first a NaN: the receiver keeps the
    /// newest, and the NaN one is still seen (this is how a NaN injected by
    /// a planner running a little ahead went uncounted on a loaded machine).
    #[test]
    fn a_superseded_message_is_still_inspected() {
        let prefix = format!("tendril-test-transport-{}", std::process::id());
        let node = node("transport-test").unwrap();
        let services = Services::open_or_create(&node, &prefix).unwrap();
        let publisher = publisher(&services.setpoint).unwrap();
        let subscriber = subscriber(&services.setpoint).unwrap();
        send(&publisher, setpoint(1, f32::NAN)).unwrap();
        send(&publisher, setpoint(2, 0.01)).unwrap();
        let mut seen = Vec::new();
        let (newest, count) =
            latest_inspecting(&subscriber, |s: &Setpoint| seen.push(s.header.seq)).unwrap();
        assert_eq!(count, 2);
        assert_eq!(newest.unwrap().header.seq, 2);
        assert_eq!(seen, [1], "the superseded message was not inspected");
        let (none, zero) = latest(&subscriber).unwrap();
        assert!(none.is_none() && zero == 0);
    }
}
