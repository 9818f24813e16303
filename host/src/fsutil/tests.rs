//! Unit tests of the output policy, the temporaries and the directory lock.

use super::*;

#[test]
fn an_output_equal_to_an_input_is_refused_whatever_its_spelling() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.tnet");
    std::fs::write(&model, b"net").unwrap();
    let spelled_otherwise = dir.path().join("sub").join("..").join("./m.tnet");
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    let err = check_distinct(
        &[("--model", &model)],
        &[("--json-out", &spelled_otherwise)],
    )
    .unwrap_err();
    assert_eq!(err.output, "--json-out");
    assert_eq!(err.other, "--model");
    assert!(err.to_string().contains("refusing to overwrite"), "{err}");
}

#[test]
fn two_outputs_naming_one_new_file_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("new.csv");
    let b = dir.path().join(".").join("new.csv");
    let err = check_distinct(&[], &[("--out", &a), ("--log", &b)]).unwrap_err();
    assert_eq!(
        (err.output.as_str(), err.other.as_str()),
        ("--log", "--out")
    );
}

#[cfg(unix)]
#[test]
fn a_symlink_to_an_input_is_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data.csv");
    std::fs::write(&data, b"x").unwrap();
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink(&data, &link).unwrap();
    assert!(check_distinct(&[("--data", &data)], &[("--out", &link)]).is_err());
}

#[test]
fn distinct_paths_pass() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.tnet");
    let b = dir.path().join("a.log.csv");
    let c = dir.path().join("data.csv");
    assert!(check_distinct(&[("--data", &c)], &[("--out", &a), ("--log", &b)]).is_ok());
}

#[test]
fn failed_fill_leaves_previous_file_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.csv");
    write_atomic(&path, b"old").unwrap();
    let err = write_atomic_with(&path, |w| {
        w.write_all(b"partial")?;
        Err(io::Error::other("interrupted"))
    });
    assert!(err.is_err());
    assert_eq!(std::fs::read(&path).unwrap(), b"old");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary file left behind");
}

#[cfg(unix)]
fn mkfifo(path: &Path) {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0, "mkfifo");
}

#[cfg(target_os = "linux")]
#[test]
fn a_full_device_is_an_error_and_stays_a_device() {
    use std::os::unix::fs::FileTypeExt;
    let full = Path::new("/dev/full");
    if !full.exists() {
        return;
    }
    let err = write_atomic(full, &[b'x'; 100_000]).unwrap_err();
    assert_eq!(err.raw_os_error(), Some(libc::ENOSPC), "{err}");
    assert!(std::fs::metadata(full)
        .unwrap()
        .file_type()
        .is_char_device());
    write_atomic(Path::new("/dev/null"), b"rows").unwrap();
    let null = std::fs::metadata("/dev/null").unwrap();
    assert!(null.file_type().is_char_device());
}

#[cfg(unix)]
#[test]
fn a_fifo_is_written_through_and_stays_a_fifo() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe");
    mkfifo(&fifo);
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap())
    };
    write_atomic_with(&fifo, |w| w.write_all(b"a,b\n1,2\n")).unwrap();
    assert_eq!(reader.join().unwrap(), b"a,b\n1,2\n");
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[cfg(unix)]
#[test]
fn a_symlink_stays_a_link_and_its_target_is_replaced() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("real")).unwrap();
    let target = dir.path().join("real").join("out.csv");
    std::fs::write(&target, b"old").unwrap();
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink("real/out.csv", &link).unwrap();
    write_atomic(&link, b"new").unwrap();
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), b"new");
    // A dangling link gets its target created.
    let dangling = dir.path().join("later.csv");
    std::os::unix::fs::symlink("real/later.csv", &dangling).unwrap();
    write_atomic(&dangling, b"made").unwrap();
    assert!(std::fs::symlink_metadata(&dangling)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(
        std::fs::read(dir.path().join("real/later.csv")).unwrap(),
        b"made"
    );
}

#[test]
fn a_dash_is_stdout_and_creates_no_file() {
    assert_eq!(sink_for(Path::new("-")).unwrap(), Sink::Stdout);
    assert!(is_stdout(Path::new("-")));
    assert!(!is_stdout(Path::new("./-")));
}

#[cfg(unix)]
#[test]
fn a_temporary_copied_through_a_device_is_removed() {
    let tmp = Temporary::for_output(Path::new("/dev/null")).unwrap();
    let path = tmp.path().to_path_buf();
    assert!(path.starts_with(std::env::temp_dir()));
    tmp.persist(Path::new("/dev/null")).unwrap();
    assert!(!path.exists());
}

#[test]
fn a_temporary_for_a_picky_writer_keeps_its_extension_and_is_cleaned_up() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = Temporary::for_output_ending(&dir.path().join("f.png"), ".tmp.png").unwrap();
    let path = tmp.path().to_path_buf();
    assert_eq!(path.extension().unwrap(), "png");
    assert!(TEMPORARIES.lock().unwrap().contains(&path));
    drop(tmp);
    assert!(!path.exists());
}

#[cfg(unix)]
#[test]
fn only_files_and_links_to_files_are_regular_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let new = dir.path().join("new.csv");
    assert!(is_regular_output(&new).unwrap());
    std::os::unix::fs::symlink("new.csv", dir.path().join("link.csv")).unwrap();
    assert!(is_regular_output(&dir.path().join("link.csv")).unwrap());
    let fifo = dir.path().join("pipe");
    mkfifo(&fifo);
    assert!(!is_regular_output(&fifo).unwrap());
    assert!(!is_regular_output(Path::new("-")).unwrap());
    assert!(!is_regular_output(Path::new("/dev/null")).unwrap());
    assert!(is_regular_output(dir.path()).is_err());
}

#[test]
fn second_signal_cleanup_removes_live_temporaries() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = Temporary::new_in(dir.path()).unwrap();
    let path = tmp.path().to_path_buf();
    remove_temporaries_where(|p| p.starts_with(dir.path()));
    assert!(!path.exists());
    drop(tmp);
    assert!(!TEMPORARIES.lock().unwrap().contains(&path));
}

#[test]
fn a_locked_directory_is_refused_with_the_holders_pid_until_released() {
    let dir = tempfile::tempdir().unwrap();
    let first = DirLock::acquire(dir.path()).unwrap();
    let err = DirLock::acquire(dir.path()).unwrap_err();
    assert!(matches!(err, LockError::InUse { .. }), "{err:?}");
    // Windows locks the lock file's bytes as well: the second handle cannot
    // read the pid there, and the message says so.
    let pid = if cfg!(windows) {
        "unknown".to_string()
    } else {
        std::process::id().to_string()
    };
    assert_eq!(
        err.to_string(),
        format!(
            "{} is in use by another tendril run (pid {pid})",
            dir.path().display(),
        )
    );
    drop(first);
    DirLock::acquire(dir.path()).expect("released on drop");
}

#[cfg(unix)]
#[test]
fn moving_into_place_keeps_a_symlink_and_replaces_its_target() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("real.json");
    std::fs::write(&target, b"old").unwrap();
    let link = dir.path().join("report.json");
    std::os::unix::fs::symlink("real.json", &link).unwrap();
    let from = dir.path().join("staged");
    std::fs::write(&from, b"new").unwrap();
    move_into_place(&from, &link).unwrap();
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), b"new");
    assert!(!from.exists());
}

#[test]
fn registered_temporary_directories_are_removed_with_the_temporaries() {
    let dir = tempfile::tempdir().unwrap();
    let staging = dir.path().join("staging");
    std::fs::create_dir_all(staging.join("sub")).unwrap();
    register_temporary_dir(&staging);
    remove_temporaries_where(|p| p.starts_with(dir.path()));
    assert!(!staging.exists());
    unregister_temporary_dir(&staging);
    assert!(!TEMPORARY_DIRS.lock().unwrap().contains(&staging));
}

#[cfg(unix)]
#[test]
fn a_capped_read_refuses_devices_directories_and_big_files() {
    let err = read_capped(Path::new("/dev/zero"), 1 << 20).unwrap_err();
    assert!(err.to_string().contains("not a regular file"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    assert!(read_capped(dir.path(), 1 << 20).is_err());
    let big = dir.path().join("big");
    File::create(&big).unwrap().set_len(3 << 20).unwrap();
    let err = read_capped(&big, 1 << 20).unwrap_err();
    assert!(
        err.to_string().contains("3 MiB is larger than the 1 MiB"),
        "{err}"
    );
    std::fs::write(&big, b"name = 1").unwrap();
    assert_eq!(read_capped(&big, 1 << 20).unwrap(), b"name = 1");
}

#[test]
fn a_line_capped_reader_fails_on_an_endless_line_and_passes_csv() {
    let mut endless = LineCapped::new(io::repeat(0));
    let mut sink = Vec::new();
    let err = io::copy(&mut endless, &mut sink).unwrap_err();
    assert!(err.to_string().contains("longer than 1 MiB"), "{err}");
    assert!(sink.len() <= LineCapped::<io::Empty>::MAX_LINE + 64 * 1024);
    let csv = "t0,t1\n1,2\n".repeat(300_000);
    let mut text = String::new();
    LineCapped::new(csv.as_bytes())
        .read_to_string(&mut text)
        .unwrap();
    assert_eq!(text, csv);
}

#[test]
fn a_name_from_a_file_is_one_plain_component() {
    for ok in ["ideal", "em-tracker", "dynamic_light.v2"] {
        assert_eq!(check_plain_name(ok), Ok(()), "{ok}");
    }
    for bad in [
        "",
        "../escaped",
        "/abs",
        "a/b",
        ".hidden",
        "..",
        "a b",
        "x\0y",
    ] {
        assert!(check_plain_name(bad).is_err(), "{bad:?} accepted");
    }
    assert!(check_plain_name(&"x".repeat(MAX_PLAIN_NAME + 1)).is_err());
}
