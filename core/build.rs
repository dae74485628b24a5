// SPDX-License-Identifier: MIT
//! Builds core's kernel and CPU-twin module trees from the shader manifest, so adding a kernel
//! edits no list:
//!
//! - `kernels_tree.rs` (included by `kernels/mod.rs`): `kernels::<capability>::<kernel>`, each
//!   holding the items `webfusion-shaders` generated for it (mirrors, typed `Bindings`, layout
//!   entries, pipeline accessor) plus, when `src/kernels/<capability>/<kernel>.rs` exists, that
//!   host file's items (custom dispatch, constants);
//! - `cpu_tree.rs` (included by `cpu/mod.rs`): `cpu::<capability>::<file>` for every file of
//!   `src/cpu/<capability>/`, the kernel twins re-exported as `cpu::<kernel>`, and the twin
//!   coverage (`TWINS`).
//!
//! A host or twin file named after no kernel of its capability is a build error, so a renamed
//! kernel cannot leave a stale twin behind.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let generated = PathBuf::from(std::env::var("DEP_WEBFUSION_SHADERS_CORE_KERNELS").expect("webfusion-shaders exports its generated code"));
    let manifest_path = PathBuf::from(std::env::var("DEP_WEBFUSION_SHADERS_MANIFEST").expect("webfusion-shaders exports its manifest"));
    println!("cargo:rerun-if-changed={}", manifest_path.display());
    let manifest = std::fs::read_to_string(&manifest_path).expect("read the shader manifest");
    // capability -> [(kernel, summary)]
    let mut kernels: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
    for line in manifest.lines() {
        let mut parts = line.splitn(3, '\t');
        let (Some(cap), Some(name), summary) = (parts.next(), parts.next(), parts.next()) else { continue };
        kernels.entry(cap.to_owned()).or_default().push((name.to_owned(), summary.unwrap_or("").to_owned()));
    }
    let kernel_capability: BTreeMap<&str, &str> = kernels.iter().flat_map(|(c, ks)| ks.iter().map(move |(k, _)| (k.as_str(), c.as_str()))).collect();

    let mut errors = Vec::new();
    let kernels_src = root.join("src/kernels");
    let cpu_src = root.join("src/cpu");
    println!("cargo:rerun-if-changed={}", kernels_src.display());
    println!("cargo:rerun-if-changed={}", cpu_src.display());

    // kernels::<capability>::<kernel>
    let mut tree = String::new();
    writeln!(tree, "/// `#[repr(C)]` mirrors of every WGSL struct a kernel binding uses (generated from naga's layout).").unwrap();
    writeln!(tree, "pub mod gpu_data {{\n    include!({:?});\n}}", generated.join("gpu_data.rs")).unwrap();
    writeln!(tree, "include!({:?});", generated.join("kernels_struct.rs")).unwrap();
    for (cap, ks) in &kernels {
        writeln!(tree, "/// The `{cap}` kernels (`shaders/wgsl/{cap}/`).\npub mod {cap} {{").unwrap();
        for (name, summary) in ks {
            writeln!(tree, "    /// `{name}`: {summary}\n    pub mod {name} {{").unwrap();
            writeln!(tree, "        include!({:?});", generated.join(format!("{name}.rs"))).unwrap();
            let host = kernels_src.join(cap).join(format!("{name}.rs"));
            if host.exists() {
                writeln!(tree, "        #[path = {:?}]\n        mod host;\n        pub use host::*;", host).unwrap();
            }
            writeln!(tree, "    }}").unwrap();
        }
        writeln!(tree, "}}").unwrap();
        for (name, _) in ks {
            writeln!(tree, "pub use {cap}::{name};").unwrap();
        }
    }
    for (cap, file) in rust_files(&kernels_src) {
        let stem = file.file_stem().expect("stem").to_string_lossy().into_owned();
        if kernel_capability.get(stem.as_str()) != Some(&cap.as_str()) {
            errors.push(format!("{}: a host file must be named after a kernel of shaders/wgsl/{cap}/", file.display()));
        }
    }
    std::fs::write(out_dir.join("kernels_tree.rs"), tree).expect("write kernels_tree.rs");

    // cpu::<capability>::<file>, twins re-exported as cpu::<kernel>
    let mut tree = String::new();
    let mut twins = Vec::new();
    let mut by_cap: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
    for (cap, file) in rust_files(&cpu_src) {
        by_cap.entry(cap).or_default().push(file);
    }
    for (cap, files) in &by_cap {
        writeln!(tree, "/// CPU twins and helpers of the `{cap}` kernels.\npub mod {cap} {{").unwrap();
        for file in files {
            let stem = file.file_stem().expect("stem").to_string_lossy().into_owned();
            writeln!(tree, "    #[path = {:?}]\n    pub mod {stem};", file).unwrap();
            match kernel_capability.get(stem.as_str()) {
                Some(c) if *c == cap => {
                    writeln!(tree, "    pub use {stem}::{stem};").unwrap();
                    twins.push(stem);
                }
                Some(c) => errors.push(format!("{}: kernel `{stem}` belongs to capability `{c}`: move its twin to src/cpu/{c}/", file.display())),
                None => {}
            }
        }
        writeln!(tree, "}}").unwrap();
        for stem in files.iter().map(|f| f.file_stem().expect("stem").to_string_lossy().into_owned()) {
            if twins.contains(&stem) {
                writeln!(tree, "pub use {cap}::{stem};").unwrap();
            }
        }
    }
    twins.sort();
    writeln!(tree, "/// Kernels with a CPU twin (`src/cpu/<capability>/<kernel>.rs`), by name.").unwrap();
    writeln!(tree, "pub const TWINS: &[&str] = &{twins:?};").unwrap();
    std::fs::write(out_dir.join("cpu_tree.rs"), tree).expect("write cpu_tree.rs");

    if !errors.is_empty() {
        for e in &errors {
            println!("cargo:warning={e}");
        }
        panic!("{}", errors.join("\n"));
    }
}

/// `(capability, file)` for every `src/<dir>/<capability>/*.rs`, sorted.
fn rust_files(dir: &Path) -> Vec<(String, PathBuf)> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else { return out };
    let mut caps: Vec<PathBuf> = entries.map(|e| e.expect("dir entry").path()).filter(|p| p.is_dir()).collect();
    caps.sort();
    for cap_dir in caps {
        println!("cargo:rerun-if-changed={}", cap_dir.display());
        let cap = cap_dir.file_name().expect("name").to_string_lossy().into_owned();
        let mut files: Vec<PathBuf> =
            std::fs::read_dir(&cap_dir).expect("readable dir").map(|e| e.expect("dir entry").path()).filter(|p| p.extension().is_some_and(|e| e == "rs")).collect();
        files.sort();
        out.extend(files.into_iter().map(|f| (cap.clone(), f)));
    }
    out
}
