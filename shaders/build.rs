// SPDX-License-Identifier: MIT
//! Stitches, validates and reflects every kernel in `wgsl/`.
//!
//! Any WGSL error prints naga's annotated message and fails the build: a stale generated file
//! can never survive a broken shader.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let wgsl_dir = root.join("wgsl");
    println!("cargo:rerun-if-changed={}", wgsl_dir.display());
    println!("cargo:rerun-if-env-changed=WGSL_DUMP_DIR");

    let mut kernel_paths: Vec<PathBuf> = std::fs::read_dir(&wgsl_dir)
        .expect("shaders/wgsl must exist")
        .map(|e| e.expect("readable dir entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    kernel_paths.sort();
    for entry in std::fs::read_dir(wgsl_dir.join("shared")).expect("shaders/wgsl/shared must exist") {
        println!("cargo:rerun-if-changed={}", entry.expect("readable dir entry").path().display());
    }

    let dump_dir = std::env::var_os("WGSL_DUMP_DIR").map(PathBuf::from);
    let mut out = String::new();
    let mut names = Vec::new();
    let mut failures = Vec::new();
    for path in &kernel_paths {
        println!("cargo:rerun-if-changed={}", path.display());
        let name = path.file_stem().expect("file stem").to_string_lossy().into_owned();
        let source = match stitch(path, &wgsl_dir.join("shared")) {
            Ok(s) => s,
            Err(e) => {
                failures.push(e);
                continue;
            }
        };
        if let Some(dir) = &dump_dir {
            std::fs::create_dir_all(dir).expect("create WGSL_DUMP_DIR");
            std::fs::write(dir.join(format!("{name}.wgsl")), &source).expect("write dumped WGSL");
        }
        match reflect(&name, path, &source) {
            Ok(code) => {
                out.push_str(&code);
                names.push(name);
            }
            Err(e) => failures.push(e),
        }
    }
    if !failures.is_empty() {
        for f in &failures {
            eprintln!("{f}");
        }
        // Print to stdout as well: cargo shows a failing build script's stdout.
        for f in &failures {
            println!("{f}");
        }
        panic!("{} WGSL kernel(s) failed validation", failures.len());
    }

    writeln!(out, "/// Every kernel, in file-name order.").unwrap();
    writeln!(out, "pub const ALL: &[&Kernel] = &[").unwrap();
    for n in &names {
        writeln!(out, "    &{},", n.to_uppercase()).unwrap();
    }
    writeln!(out, "];").unwrap();
    let out_path = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("kernels.rs");
    std::fs::write(out_path, out).expect("write kernels.rs");
}

/// Replaces each `#import name` line with `shared/name.wgsl` (once per kernel, recursively).
fn stitch(path: &Path, shared_dir: &Path) -> Result<String, String> {
    let mut seen = BTreeSet::new();
    let mut out = String::new();
    stitch_into(path, shared_dir, &mut seen, &mut out)?;
    Ok(out)
}

fn stitch_into(path: &Path, shared_dir: &Path, seen: &mut BTreeSet<String>, out: &mut String) -> Result<(), String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("error: cannot read {}: {e}", path.display()))?;
    for (line_ix, line) in text.lines().enumerate() {
        if let Some(rest) = line.trim_start().strip_prefix("#import ") {
            let import = rest.trim();
            if seen.insert(import.to_owned()) {
                let import_path = shared_dir.join(format!("{import}.wgsl"));
                if !import_path.exists() {
                    return Err(format!(
                        "error: {}:{}: `#import {import}` but {} does not exist",
                        path.display(),
                        line_ix + 1,
                        import_path.display()
                    ));
                }
                writeln!(out, "// ---- begin import {import} ----").unwrap();
                stitch_into(&import_path, shared_dir, seen, out)?;
                writeln!(out, "// ---- end import {import} ----").unwrap();
            }
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    Ok(())
}

fn reflect(name: &str, path: &Path, source: &str) -> Result<String, String> {
    let shown = path.display().to_string();
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string_with_path(source, &shown))?;
    let mut validator = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty());
    validator.validate(&module).map_err(|e| e.emit_to_string_with_path(source, &shown))?;

    let compute: Vec<_> = module.entry_points.iter().filter(|e| e.stage == naga::ShaderStage::Compute).collect();
    if compute.len() != 1 || module.entry_points.len() != 1 {
        return Err(format!("error: {shown}: a kernel file must hold exactly one @compute entry point, found {}", module.entry_points.len()));
    }
    let ep = compute[0];
    if ep.workgroup_size_overrides.is_some() {
        return Err(format!("error: {shown}: workgroup size must be a literal so the host can reflect it"));
    }
    let gctx = module.to_ctx();

    let mut bindings = Vec::new();
    let mut struct_types = BTreeSet::new();
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let kind = match var.space {
            naga::AddressSpace::Uniform => "Uniform",
            naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => "StorageReadWrite",
            naga::AddressSpace::Storage { .. } => "StorageRead",
            other => return Err(format!("error: {shown}: binding {:?} uses unsupported address space {other:?}", var.name)),
        };
        let ty = &module.types[var.ty];
        let min_size = match &ty.inner {
            naga::TypeInner::Array { stride, size: naga::ArraySize::Dynamic, .. } => *stride,
            other => other.size(gctx),
        };
        collect_structs(&module, var.ty, &mut struct_types);
        bindings.push((rb.group, rb.binding, var.name.clone().unwrap_or_default(), kind, min_size));
    }
    bindings.sort_by_key(|b| (b.0, b.1));

    let upper = name.to_uppercase();
    let mut code = String::new();
    writeln!(code, "/// Kernel `{name}` (from `shaders/wgsl/{name}.wgsl`).").unwrap();
    writeln!(code, "pub const {upper}: Kernel = Kernel {{").unwrap();
    writeln!(code, "    name: {name:?},").unwrap();
    writeln!(code, "    source: {source:?},").unwrap();
    writeln!(code, "    entry_point: {:?},", ep.name).unwrap();
    writeln!(code, "    workgroup_size: {:?},", ep.workgroup_size).unwrap();
    writeln!(code, "    bindings: &[").unwrap();
    for (g, b, n, k, s) in &bindings {
        writeln!(code, "        Binding {{ group: {g}, binding: {b}, name: {n:?}, kind: BindingKind::{k}, min_size_bytes: {s} }},").unwrap();
    }
    writeln!(code, "    ],").unwrap();
    writeln!(code, "    structs: &[").unwrap();
    for handle in struct_types {
        let ty = &module.types[handle];
        if let naga::TypeInner::Struct { members, span } = &ty.inner {
            let sname = ty.name.clone().unwrap_or_default();
            write!(code, "        StructLayout {{ name: {sname:?}, size_bytes: {span}, members: &[").unwrap();
            for m in members {
                write!(code, "StructMember {{ name: {:?}, offset_bytes: {} }}, ", m.name.clone().unwrap_or_default(), m.offset).unwrap();
            }
            writeln!(code, "] }},").unwrap();
        }
    }
    writeln!(code, "    ],").unwrap();
    writeln!(code, "}};").unwrap();
    Ok(code)
}

fn collect_structs(module: &naga::Module, ty: naga::Handle<naga::Type>, out: &mut BTreeSet<naga::Handle<naga::Type>>) {
    match &module.types[ty].inner {
        naga::TypeInner::Struct { members, .. } if out.insert(ty) => {
            for m in members {
                collect_structs(module, m.ty, out);
            }
        }
        naga::TypeInner::Array { base, .. } => collect_structs(module, *base, out),
        _ => {}
    }
}
