// SPDX-License-Identifier: MIT
//! Builds the test target's module tree, so a new test file needs no `mod` line:
//! `kernels/<capability>/<file>.rs` become `<capability>::<file>` and `kernels/<file>.rs` (but
//! `main.rs`) top-level modules. Also lists the kernels that have no test file
//! (`kernels/<capability>/<kernel>.rs`), which `layout::every_kernel_has_a_twin_and_a_test`
//! requires to be none, and includes the generated layout checks.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest_path = PathBuf::from(std::env::var("DEP_WEBFUSION_SHADERS_MANIFEST").expect("webfusion-shaders exports its manifest"));
    let layout_checks = PathBuf::from(std::env::var("DEP_WEBFUSION_SHADERS_LAYOUT_CHECKS").expect("webfusion-shaders exports its layout checks"));
    println!("cargo:rerun-if-changed={}", manifest_path.display());
    let manifest = std::fs::read_to_string(&manifest_path).expect("read the shader manifest");
    let dir = root.join("kernels");
    println!("cargo:rerun-if-changed={}", dir.display());

    let mut tree = String::new();
    let mut top: Vec<PathBuf> = files(&dir).into_iter().filter(|f| f.file_stem().is_some_and(|s| s != "main")).collect();
    top.sort();
    for f in &top {
        writeln!(tree, "#[path = {:?}]\npub(crate) mod {};", f, stem(f)).unwrap();
    }
    let mut caps: Vec<PathBuf> = std::fs::read_dir(&dir).expect("tests/kernels").map(|e| e.expect("entry").path()).filter(|p| p.is_dir()).collect();
    caps.sort();
    for cap in &caps {
        println!("cargo:rerun-if-changed={}", cap.display());
        writeln!(tree, "pub(crate) mod {} {{", stem(cap)).unwrap();
        for f in files(cap) {
            writeln!(tree, "    #[path = {:?}]\n    pub(crate) mod {};", f, stem(&f)).unwrap();
        }
        writeln!(tree, "}}").unwrap();
    }
    let untested: Vec<String> = manifest
        .lines()
        .filter_map(|l| {
            let mut p = l.split('\t');
            let (cap, name) = (p.next()?, p.next()?);
            (!dir.join(cap).join(format!("{name}.rs")).exists()).then(|| format!("{cap}/{name}"))
        })
        .collect();
    writeln!(tree, "/// Kernels without `tests/kernels/<capability>/<kernel>.rs`.\nconst KERNELS_WITHOUT_TESTS: &[&str] = &{untested:?};").unwrap();
    writeln!(tree, "mod generated_layout_checks {{\n    use webfusion_tests::check_layout;\n    include!({layout_checks:?});\n}}").unwrap();
    std::fs::write(out_dir.join("test_tree.rs"), tree).expect("write test_tree.rs");
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir).expect("readable dir").map(|e| e.expect("entry").path()).filter(|p| p.extension().is_some_and(|e| e == "rs")).collect();
    v.sort();
    v
}

fn stem(p: &Path) -> String {
    p.file_stem().expect("stem").to_string_lossy().into_owned()
}
