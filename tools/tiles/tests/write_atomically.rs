//! `format::write_atomically`, which `tiletool export` and `vkterrain`'s summary and trace
//! share: the file appears whole or not at all, and no temporary is left behind either way.

use tiles::format::{temp_path, write_atomically};

#[test]
fn replaces_the_file_and_leaves_no_temporary() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run.json");
    write_atomically(&out, b"first").expect("write");
    write_atomically(&out, b"second, longer").expect("rewrite");
    assert_eq!(std::fs::read(&out).expect("read"), b"second, longer");
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .expect("list")
        .map(|e| e.expect("entry").file_name())
        .collect();
    assert_eq!(names, ["run.json"], "only the file itself");
}

#[test]
fn a_failed_write_leaves_neither_file_nor_temporary() {
    let dir = tempfile::tempdir().expect("temp dir");
    // The rename fails: a directory stands where the file goes.
    let out = dir.path().join("taken");
    std::fs::create_dir(&out).expect("dir");
    assert!(write_atomically(&out, b"bytes").is_err());
    assert!(out.is_dir(), "the directory is left as it was");
    assert!(
        !temp_path(&out).expect("temp path").exists(),
        "temporary removed"
    );
    // The temporary cannot be created: the folder does not exist.
    let missing = dir.path().join("no/such/folder/out.png");
    assert!(write_atomically(&missing, b"bytes").is_err());
    assert!(!missing.exists());
    // A path that names no file.
    assert!(write_atomically(std::path::Path::new("/"), b"bytes").is_err());
}
