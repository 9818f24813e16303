//! A sim run's files are published by the output policy (issue 31): an
//! output path that is a symlink stays a link and its target is replaced,
//! as `fsutil`'s atomic write does, instead of the link being renamed over.

#![cfg(unix)]

use tendril::ipc::sim::workdir::RunDir;

#[test]
fn publishing_a_run_keeps_a_symlinked_output_a_link() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let kept = tmp.path().join("kept-report.json");
    std::fs::write(&kept, "old").unwrap();
    std::os::unix::fs::symlink(&kept, out.join("report.json")).unwrap();

    let dir = RunDir::create(&out).unwrap();
    std::fs::write(dir.file("report.json"), "new").unwrap();
    dir.publish().unwrap();

    let link = std::fs::symlink_metadata(out.join("report.json")).unwrap();
    assert!(
        link.file_type().is_symlink(),
        "the link was replaced by a file"
    );
    assert_eq!(std::fs::read_to_string(&kept).unwrap(), "new");
}
