// SPDX-License-Identifier: MIT
//! Stitches, validates and reflects every kernel in `wgsl/<capability>/<kernel>.wgsl`, and
//! generates everything that used to be kept by hand:
//!
//! - `kernels.rs` (this crate): one [`Kernel`] constant per kernel and `ALL`;
//! - `core_kernels/` (for `webfusion-core`): the `#[repr(C)]` mirror of every WGSL struct a
//!   binding uses (`gpu_data`), per kernel a typed `Bindings` struct in WGSL binding order,
//!   its bind group layout entries, and the `Kernels` struct with one pipeline per kernel;
//! - `layout_checks.rs` (for `webfusion-tests`): a size/offset check of every mirror against
//!   naga's layout;
//! - `manifest.txt`: `capability<TAB>kernel<TAB>summary` per kernel, from which core and the
//!   tests generate their module trees and coverage lists.
//!
//! The three generated paths reach dependents' build scripts as `DEP_WEBFUSION_SHADERS_*`
//! (this package `links` to "webfusion-shaders" for exactly that). Any WGSL error prints naga's
//! annotated message and fails the build: a stale generated file can never survive a broken
//! shader.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Folder of `#import`able WGSL, not kernels.
const SHARED_DIR: &str = "shared";

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let wgsl_dir = root.join("wgsl");
    println!("cargo:rerun-if-changed={}", wgsl_dir.display());
    println!("cargo:rerun-if-env-changed=WGSL_DUMP_DIR");

    let kernel_files = discover(&wgsl_dir);
    let dump_dir = std::env::var_os("WGSL_DUMP_DIR").map(PathBuf::from);
    let mut kernels = Vec::new();
    let mut failures = Vec::new();
    let mut seen_names = BTreeMap::new();
    for (capability, path) in &kernel_files {
        let name = path.file_stem().expect("file stem").to_string_lossy().into_owned();
        if let Some(other) = seen_names.insert(name.clone(), path.clone()) {
            failures.push(format!("error: two kernels are called `{name}`: {} and {}", other.display(), path.display()));
            continue;
        }
        if !is_identifier(&name) {
            failures.push(format!("error: {}: a kernel's file name must be a snake_case identifier", path.display()));
            continue;
        }
        let source = match stitch(path, &wgsl_dir.join(SHARED_DIR)) {
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
        match reflect(capability, &name, path, &source) {
            Ok(k) => kernels.push(k),
            Err(e) => failures.push(e),
        }
    }
    let structs = match merge_structs(&kernels) {
        Ok(s) => s,
        Err(e) => {
            failures.push(e);
            BTreeMap::new()
        }
    };
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

    let write = |file: &str, text: String| {
        let path = out_dir.join(file);
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("write {}: {e}", path.display()));
        path
    };
    write("kernels.rs", shader_crate_code(&kernels));
    let core = out_dir.join("core_kernels");
    write_core_files(&core, &kernels, &structs);
    let layout = write("layout_checks.rs", layout_checks_code(&kernels, &structs));
    let manifest = write("manifest.txt", manifest(&kernels));
    // Read by dependents' build scripts as DEP_WEBFUSION_SHADERS_<KEY>.
    println!("cargo:core_kernels={}", core.display());
    println!("cargo:layout_checks={}", layout.display());
    println!("cargo:manifest={}", manifest.display());
}

/// `(capability, path)` of every kernel: `wgsl/<capability>/<kernel>.wgsl`, sorted.
fn discover(wgsl_dir: &Path) -> Vec<(String, PathBuf)> {
    let mut out = Vec::new();
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(wgsl_dir).expect("shaders/wgsl must exist").map(|e| e.expect("readable dir entry").path()).collect();
    dirs.sort();
    for dir in dirs {
        if dir.extension().is_some_and(|e| e == "wgsl") {
            panic!("{}: kernels live in a capability folder, wgsl/<capability>/<kernel>.wgsl", dir.display());
        }
        if !dir.is_dir() {
            continue;
        }
        let capability = dir.file_name().expect("dir name").to_string_lossy().into_owned();
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .expect("readable capability folder")
            .map(|e| e.expect("readable dir entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
            .collect();
        files.sort();
        for f in files {
            println!("cargo:rerun-if-changed={}", f.display());
            if capability != SHARED_DIR {
                out.push((capability.clone(), f));
            }
        }
        println!("cargo:rerun-if-changed={}", dir.display());
    }
    out
}

fn is_identifier(s: &str) -> bool {
    !s.is_empty() && s.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_') && !s.starts_with(|c: char| c.is_ascii_digit())
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
                    return Err(format!("error: {}:{}: `#import {import}` but {} does not exist", path.display(), line_ix + 1, import_path.display()));
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

/// One reflected binding.
struct BindingInfo {
    group: u32,
    binding: u32,
    name: String,
    /// Variant of `webfusion_shaders::BindingKind`, as Rust source.
    kind: String,
    /// What the typed bindings field holds: `buffer`, `texture` or `sampler`.
    resource: &'static str,
    /// `wgpu::BindingType` for the layout, as Rust source.
    layout: String,
    min_size_bytes: u32,
    /// The WGSL declaration's type, e.g. `array<vec4<f32>>`.
    wgsl_type: String,
    doc: String,
}

/// One reflected struct member.
#[derive(Clone, PartialEq)]
struct MemberInfo {
    name: String,
    offset: u32,
    size: u32,
    /// Rust mirror type, or `None` if the member cannot be mirrored (runtime-sized array).
    rust_type: Option<String>,
    wgsl_type: String,
    doc: String,
}

/// One reflected struct.
#[derive(Clone, PartialEq)]
struct StructInfo {
    name: String,
    size: u32,
    members: Vec<MemberInfo>,
    doc: String,
}

impl StructInfo {
    fn mirrorable(&self) -> bool {
        self.members.iter().all(|m| m.rust_type.is_some())
    }
}

struct KernelInfo {
    capability: String,
    name: String,
    summary: String,
    source: String,
    entry_point: String,
    workgroup_size: [u32; 3],
    bindings: Vec<BindingInfo>,
    structs: Vec<StructInfo>,
    cpu_twin_exemption: Option<String>,
}

fn reflect(capability: &str, name: &str, path: &Path, source: &str) -> Result<KernelInfo, String> {
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
    let docs = SourceDocs::parse(source);

    let mut bindings = Vec::new();
    let mut struct_types = BTreeSet::new();
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let var_name = var.name.clone().unwrap_or_default();
        let ty = &module.types[var.ty];
        let wgsl_type = type_name(&module, var.ty);
        let (kind, resource, layout, min_size) = match (&var.space, &ty.inner) {
            (naga::AddressSpace::Uniform, inner) => {
                ("Uniform".to_owned(), "buffer", buffer_layout("wgpu::BufferBindingType::Uniform", inner.size(gctx)), inner.size(gctx))
            }
            (naga::AddressSpace::Storage { access }, inner) => {
                let min = match inner {
                    naga::TypeInner::Array { stride, size: naga::ArraySize::Dynamic, .. } => *stride,
                    naga::TypeInner::Struct { members, .. } => match members.last().map(|m| &module.types[m.ty].inner) {
                        Some(naga::TypeInner::Array { stride, size: naga::ArraySize::Dynamic, .. }) => members.last().map_or(0, |m| m.offset) + stride,
                        _ => inner.size(gctx),
                    },
                    other => other.size(gctx),
                };
                let writable = access.contains(naga::StorageAccess::STORE);
                let kind = if writable { "StorageReadWrite" } else { "StorageRead" };
                (kind.to_owned(), "buffer", buffer_layout(&format!("wgpu::BufferBindingType::Storage {{ read_only: {} }}", !writable), min), min)
            }
            (naga::AddressSpace::Handle, naga::TypeInner::Image { dim, arrayed, class }) => {
                let dimension = view_dimension(*dim, *arrayed).map_err(|e| format!("error: {shown}: binding `{var_name}`: {e}"))?;
                match class {
                    naga::ImageClass::Storage { format, access } => {
                        let access_rs = match (access.contains(naga::StorageAccess::LOAD), access.contains(naga::StorageAccess::STORE)) {
                            (true, true) => "ReadWrite",
                            (true, false) => "ReadOnly",
                            _ => "WriteOnly",
                        };
                        let format_rs = format!("{format:?}");
                        (
                            format!("StorageTexture {{ format: {format_rs:?}, access: StorageTextureAccess::{access_rs}, dimension: {:?} }}", dimension.0),
                            "texture",
                            format!(
                                "wgpu::BindingType::StorageTexture {{ access: wgpu::StorageTextureAccess::{access_rs}, format: wgpu::TextureFormat::{format_rs}, view_dimension: wgpu::TextureViewDimension::{} }}",
                                dimension.1
                            ),
                            0,
                        )
                    }
                    naga::ImageClass::Sampled { kind, multi } => {
                        // A float texture only used with textureLoad binds any float format
                        // (r32float included) as unfilterable; with a sampler it is filterable.
                        let uses_sampler = module.global_variables.iter().any(|(_, g)| matches!(module.types[g.ty].inner, naga::TypeInner::Sampler { .. }));
                        let (sample, sample_rs) = match kind {
                            naga::ScalarKind::Float if uses_sampler => ("Float", "wgpu::TextureSampleType::Float { filterable: true }".to_owned()),
                            naga::ScalarKind::Float => ("UnfilterableFloat", "wgpu::TextureSampleType::Float { filterable: false }".to_owned()),
                            naga::ScalarKind::Sint => ("Sint", "wgpu::TextureSampleType::Sint".to_owned()),
                            naga::ScalarKind::Uint => ("Uint", "wgpu::TextureSampleType::Uint".to_owned()),
                            other => return Err(format!("error: {shown}: binding `{var_name}`: unsupported texel kind {other:?}")),
                        };
                        (
                            format!("Texture {{ sample_type: TextureSampleType::{sample}, dimension: {:?}, multisampled: {multi} }}", dimension.0),
                            "texture",
                            format!("wgpu::BindingType::Texture {{ sample_type: {sample_rs}, view_dimension: wgpu::TextureViewDimension::{}, multisampled: {multi} }}", dimension.1),
                            0,
                        )
                    }
                    other => return Err(format!("error: {shown}: binding `{var_name}`: unsupported image class {other:?}")),
                }
            }
            (naga::AddressSpace::Handle, naga::TypeInner::Sampler { comparison }) => {
                let ty = if *comparison { "Comparison" } else { "Filtering" };
                (format!("Sampler {{ comparison: {comparison} }}"), "sampler", format!("wgpu::BindingType::Sampler(wgpu::SamplerBindingType::{ty})"), 0)
            }
            (other, _) => return Err(format!("error: {shown}: binding `{var_name}` uses unsupported address space {other:?}")),
        };
        collect_structs(&module, var.ty, &mut struct_types);
        bindings.push(BindingInfo {
            group: rb.group,
            binding: rb.binding,
            doc: docs.binding(&var_name).unwrap_or_default(),
            name: var_name,
            kind,
            resource,
            layout,
            min_size_bytes: min_size,
            wgsl_type,
        });
    }
    bindings.sort_by_key(|b| (b.group, b.binding));
    if let Some(b) = bindings.iter().find(|b| b.group != 0) {
        return Err(format!("error: {shown}: binding `{}` is in group {}; kernels use group 0 only", b.name, b.group));
    }
    let mut rust_names = BTreeSet::new();
    for b in &bindings {
        if !rust_names.insert(b.name.clone()) || !is_identifier(&b.name) {
            return Err(format!("error: {shown}: binding `{}` must be a unique snake_case name (it names a Rust field)", b.name));
        }
    }

    let mut structs = Vec::new();
    for handle in struct_types {
        let ty = &module.types[handle];
        let naga::TypeInner::Struct { members, span } = &ty.inner else { continue };
        let sname = ty.name.clone().unwrap_or_default();
        let members = members
            .iter()
            .map(|m| {
                let mname = m.name.clone().unwrap_or_default();
                MemberInfo {
                    doc: docs.member(&sname, &mname).unwrap_or_default(),
                    offset: m.offset,
                    size: module.types[m.ty].inner.size(gctx),
                    rust_type: rust_type(&module, m.ty),
                    wgsl_type: type_name(&module, m.ty),
                    name: mname,
                }
            })
            .collect();
        structs.push(StructInfo { doc: docs.struct_doc(&sname).unwrap_or_default(), name: sname, size: *span, members });
    }

    Ok(KernelInfo {
        capability: capability.to_owned(),
        name: name.to_owned(),
        summary: docs.module_summary(),
        cpu_twin_exemption: docs.cpu_twin_exemption(),
        source: source.to_owned(),
        entry_point: ep.name.clone(),
        workgroup_size: ep.workgroup_size,
        bindings,
        structs,
    })
}

fn buffer_layout(ty: &str, min_size: u32) -> String {
    let min = if min_size == 0 { "None".to_owned() } else { format!("wgpu::BufferSize::new({min_size})") };
    format!("wgpu::BindingType::Buffer {{ ty: {ty}, has_dynamic_offset: false, min_binding_size: {min} }}")
}

/// (`webfusion_shaders::TextureDimension` variant, `wgpu::TextureViewDimension` variant).
fn view_dimension(dim: naga::ImageDimension, arrayed: bool) -> Result<(&'static str, &'static str), String> {
    use naga::ImageDimension as D;
    Ok(match (dim, arrayed) {
        (D::D1, false) => ("D1", "D1"),
        (D::D2, false) => ("D2", "D2"),
        (D::D2, true) => ("D2Array", "D2Array"),
        (D::D3, false) => ("D3", "D3"),
        (D::Cube, false) => ("Cube", "Cube"),
        (D::Cube, true) => ("CubeArray", "CubeArray"),
        (d, a) => return Err(format!("unsupported texture dimension {d:?} (arrayed: {a})")),
    })
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

fn scalar_name(s: naga::Scalar) -> &'static str {
    match (s.kind, s.width) {
        (naga::ScalarKind::Float, 4) => "f32",
        (naga::ScalarKind::Uint, 4) => "u32",
        (naga::ScalarKind::Sint, 4) => "i32",
        (naga::ScalarKind::Float, 2) => "f16",
        (naga::ScalarKind::Bool, _) => "bool",
        _ => "?",
    }
}

/// The WGSL spelling of a type, for docs.
fn type_name(module: &naga::Module, ty: naga::Handle<naga::Type>) -> String {
    let t = &module.types[ty];
    match &t.inner {
        naga::TypeInner::Scalar(s) => scalar_name(*s).to_owned(),
        naga::TypeInner::Atomic(s) => format!("atomic<{}>", scalar_name(*s)),
        naga::TypeInner::Vector { size, scalar } => format!("vec{}<{}>", *size as u8, scalar_name(*scalar)),
        naga::TypeInner::Matrix { columns, rows, scalar } => format!("mat{}x{}<{}>", *columns as u8, *rows as u8, scalar_name(*scalar)),
        naga::TypeInner::Array { base, size: naga::ArraySize::Constant(n), .. } => format!("array<{}, {n}>", type_name(module, *base)),
        naga::TypeInner::Array { base, .. } => format!("array<{}>", type_name(module, *base)),
        naga::TypeInner::Struct { .. } => t.name.clone().unwrap_or_default(),
        naga::TypeInner::Image { .. } => "texture".to_owned(),
        naga::TypeInner::Sampler { comparison: false } => "sampler".to_owned(),
        naga::TypeInner::Sampler { comparison: true } => "sampler_comparison".to_owned(),
        other => format!("{other:?}"),
    }
}

/// The `#[repr(C)]` Rust type laid out exactly like `ty` in a host-shareable WGSL struct, or
/// `None` where no fixed-size mirror exists.
fn rust_type(module: &naga::Module, ty: naga::Handle<naga::Type>) -> Option<String> {
    let t = &module.types[ty];
    let scalar = |s: naga::Scalar| match (s.kind, s.width) {
        (naga::ScalarKind::Float, 4) => Some("f32"),
        (naga::ScalarKind::Uint, 4) => Some("u32"),
        (naga::ScalarKind::Sint, 4) => Some("i32"),
        _ => None,
    };
    match &t.inner {
        naga::TypeInner::Scalar(s) | naga::TypeInner::Atomic(s) => scalar(*s).map(str::to_owned),
        naga::TypeInner::Vector { size, scalar: s } => Some(format!("[{}; {}]", scalar(*s)?, *size as u8)),
        // Columns are vectors of `rows`, vec3 columns padded to 16 bytes.
        naga::TypeInner::Matrix { columns, rows, scalar: s } => {
            let stride = if *rows as u8 == 2 { 2 } else { 4 };
            Some(format!("[[{}; {stride}]; {}]", scalar(*s)?, *columns as u8))
        }
        naga::TypeInner::Array { base, size: naga::ArraySize::Constant(n), stride } => {
            let element = rust_type(module, *base)?;
            let gctx = module.to_ctx();
            let element_size = module.types[*base].inner.size(gctx);
            if *stride == element_size {
                Some(format!("[{element}; {n}]"))
            } else if matches!(module.types[*base].inner, naga::TypeInner::Vector { size: naga::VectorSize::Tri, .. }) && *stride == 16 {
                let s = match &module.types[*base].inner {
                    naga::TypeInner::Vector { scalar: s, .. } => scalar(*s)?,
                    _ => return None,
                };
                Some(format!("[[{s}; 4]; {n}]"))
            } else {
                None
            }
        }
        naga::TypeInner::Struct { .. } => t.name.clone(),
        _ => None,
    }
}

/// Comments in the WGSL source, attached to what follows them.
struct SourceDocs {
    /// The `//!` block at the top.
    module: Vec<String>,
    structs: BTreeMap<String, String>,
    members: BTreeMap<(String, String), String>,
    bindings: BTreeMap<String, String>,
}

impl SourceDocs {
    /// Line-based: `// ...` lines right above a struct, a member or a binding (or a trailing
    /// `// ...` on the same line) document it. Import banners are not docs.
    fn parse(source: &str) -> Self {
        let mut docs = Self { module: Vec::new(), structs: BTreeMap::new(), members: BTreeMap::new(), bindings: BTreeMap::new() };
        let mut pending: Vec<String> = Vec::new();
        let mut current_struct: Option<String> = None;
        let mut in_module_doc = true;
        for raw in source.lines() {
            let line = raw.trim();
            if let Some(doc) = line.strip_prefix("//!") {
                if in_module_doc {
                    docs.module.push(doc.trim().to_owned());
                }
                continue;
            }
            if !line.starts_with("// SPDX") && !line.is_empty() {
                in_module_doc = false;
            }
            if line.starts_with("// ---- ") {
                pending.clear();
                continue;
            }
            if let Some(comment) = line.strip_prefix("//") {
                pending.push(comment.trim().to_owned());
                continue;
            }
            let (code, trailing) = match line.find("//") {
                Some(i) => (line[..i].trim(), Some(line[i + 2..].trim().to_owned())),
                None => (line, None),
            };
            let mut doc = std::mem::take(&mut pending);
            doc.extend(trailing);
            let doc = doc.join(" ");
            if let Some(rest) = code.strip_prefix("struct ") {
                let name = rest.trim_end_matches('{').trim().to_owned();
                if !doc.is_empty() {
                    docs.structs.insert(name.clone(), doc);
                }
                current_struct = Some(name);
            } else if code.starts_with('}') {
                current_struct = None;
            } else if let Some(s) = &current_struct {
                if let Some((member, _)) = code.split_once(':')
                    && !doc.is_empty()
                {
                    let member = member.trim().trim_start_matches("@align").trim();
                    let member = member.rsplit(' ').next().unwrap_or(member).to_owned();
                    docs.members.insert((s.clone(), member), doc);
                }
            } else if code.starts_with("@group(")
                && let Some(after_var) = code.split("var").nth(1)
                && let Some(name) = after_var.split('>').next_back().or(Some(after_var))
                && let Some((name, _)) = name.split_once(':')
                && !doc.is_empty()
            {
                docs.bindings.insert(name.trim().to_owned(), doc);
            }
        }
        docs
    }

    fn module_summary(&self) -> String {
        let text = self.module.iter().take_while(|l| !l.is_empty()).cloned().collect::<Vec<_>>().join(" ");
        // First sentence.
        match text.find(". ") {
            Some(i) => text[..=i].to_owned(),
            None => text,
        }
    }

    /// `//! cpu-twin: none: <reason>` exempts a kernel from having a CPU twin.
    fn cpu_twin_exemption(&self) -> Option<String> {
        self.module.iter().find_map(|l| l.strip_prefix("cpu-twin: none:").map(|r| r.trim().to_owned()))
    }

    fn struct_doc(&self, name: &str) -> Option<String> {
        self.structs.get(name).cloned()
    }

    fn member(&self, s: &str, m: &str) -> Option<String> {
        self.members.get(&(s.to_owned(), m.to_owned())).cloned()
    }

    fn binding(&self, name: &str) -> Option<String> {
        self.bindings.get(name).cloned()
    }
}

/// Every struct used by any kernel, by name; one name must mean one layout everywhere.
fn merge_structs(kernels: &[KernelInfo]) -> Result<BTreeMap<String, StructInfo>, String> {
    let mut out: BTreeMap<String, (StructInfo, String)> = BTreeMap::new();
    for k in kernels {
        for s in &k.structs {
            match out.get_mut(&s.name) {
                Some((existing, first)) => {
                    let same_layout = existing.size == s.size
                        && existing.members.len() == s.members.len()
                        && existing.members.iter().zip(&s.members).all(|(a, b)| a.name == b.name && a.offset == b.offset && a.wgsl_type == b.wgsl_type);
                    if !same_layout {
                        return Err(format!("error: struct `{}` is laid out differently in kernels `{first}` and `{}`; give one of them another name", s.name, k.name));
                    }
                    // Keep whichever copy carries docs.
                    if existing.doc.is_empty() {
                        existing.doc.clone_from(&s.doc);
                    }
                    for (a, b) in existing.members.iter_mut().zip(&s.members) {
                        if a.doc.is_empty() {
                            a.doc.clone_from(&b.doc);
                        }
                    }
                }
                None => {
                    out.insert(s.name.clone(), (s.clone(), k.name.clone()));
                }
            }
        }
    }
    Ok(out.into_iter().map(|(k, (s, _))| (k, s)).collect())
}

fn shader_crate_code(kernels: &[KernelInfo]) -> String {
    let mut code = String::new();
    for k in kernels {
        let upper = k.name.to_uppercase();
        writeln!(code, "/// Kernel `{}` (`shaders/wgsl/{}/{}.wgsl`): {}", k.name, k.capability, k.name, k.summary).unwrap();
        writeln!(code, "pub const {upper}: Kernel = Kernel {{").unwrap();
        writeln!(code, "    name: {:?},", k.name).unwrap();
        writeln!(code, "    capability: {:?},", k.capability).unwrap();
        writeln!(code, "    summary: {:?},", k.summary).unwrap();
        writeln!(code, "    source: {:?},", k.source).unwrap();
        writeln!(code, "    entry_point: {:?},", k.entry_point).unwrap();
        writeln!(code, "    workgroup_size: {:?},", k.workgroup_size).unwrap();
        writeln!(code, "    cpu_twin_exemption: {:?},", k.cpu_twin_exemption).unwrap();
        writeln!(code, "    bindings: &[").unwrap();
        for b in &k.bindings {
            writeln!(
                code,
                "        Binding {{ group: {}, binding: {}, name: {:?}, kind: BindingKind::{}, min_size_bytes: {}, wgsl_type: {:?} }},",
                b.group, b.binding, b.name, b.kind, b.min_size_bytes, b.wgsl_type
            )
            .unwrap();
        }
        writeln!(code, "    ],").unwrap();
        writeln!(code, "    structs: &[").unwrap();
        for s in &k.structs {
            write!(code, "        StructLayout {{ name: {:?}, size_bytes: {}, members: &[", s.name, s.size).unwrap();
            for m in &s.members {
                write!(code, "StructMember {{ name: {:?}, offset_bytes: {}, size_bytes: {}, wgsl_type: {:?} }}, ", m.name, m.offset, m.size, m.wgsl_type).unwrap();
            }
            writeln!(code, "] }},").unwrap();
        }
        writeln!(code, "    ],").unwrap();
        writeln!(code, "}};").unwrap();
    }
    writeln!(code, "/// Every kernel, by capability then name.").unwrap();
    writeln!(code, "pub const ALL: &[&Kernel] = &[").unwrap();
    for k in kernels {
        writeln!(code, "    &{},", k.name.to_uppercase()).unwrap();
    }
    writeln!(code, "];").unwrap();
    code
}

/// Escapes text for a `///` line.
fn doc_line(text: &str) -> String {
    text.replace('\n', " ")
}

/// The code `webfusion-core` includes in `core::kernels`, one file each: `gpu_data.rs` (the
/// struct mirrors), `<kernel>.rs` (the items of one kernel's module: its typed `Bindings`, layout
/// entries, workgroup size and pipeline accessor) and `kernels_struct.rs` (`Kernels`). Core's own
/// build script places the kernel files in its module tree (`kernels::<capability>::<kernel>`).
fn write_core_files(dir: &Path, kernels: &[KernelInfo], structs: &BTreeMap<String, StructInfo>) {
    std::fs::create_dir_all(dir).expect("create core_kernels dir");
    let write = |file: String, text: String| std::fs::write(dir.join(&file), text).unwrap_or_else(|e| panic!("write {file}: {e}"));

    let mut code = String::new();
    for s in structs.values().filter(|s| s.mirrorable()) {
        let doc = if s.doc.is_empty() { format!("Mirror of WGSL `{}`.", s.name) } else { format!("{} (mirror of WGSL `{}`)", doc_line(&s.doc), s.name) };
        writeln!(code, "/// {doc}").unwrap();
        writeln!(code, "#[repr(C)]").unwrap();
        writeln!(code, "#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]").unwrap();
        writeln!(code, "pub struct {} {{", s.name).unwrap();
        let mut at = 0u32;
        let mut pad_ix = 0;
        for m in &s.members {
            if m.offset > at {
                writeln!(code, "    #[doc(hidden)]\n    pub _wgsl_align{pad_ix}: [u32; {}],", (m.offset - at) / 4).unwrap();
                pad_ix += 1;
            }
            let doc = if m.doc.is_empty() { format!("WGSL `{}: {}`.", m.name, m.wgsl_type) } else { doc_line(&m.doc) };
            writeln!(code, "    /// {doc}").unwrap();
            writeln!(code, "    pub {}: {},", m.name, m.rust_type.as_deref().unwrap_or("()")).unwrap();
            at = m.offset + m.size;
        }
        if s.size > at {
            writeln!(code, "    #[doc(hidden)]\n    pub _wgsl_align{pad_ix}: [u32; {}],", (s.size - at) / 4).unwrap();
        }
        writeln!(code, "}}").unwrap();
        writeln!(code, "impl Default for {} {{\n    fn default() -> Self {{\n        bytemuck::Zeroable::zeroed()\n    }}\n}}", s.name).unwrap();
    }
    write("gpu_data.rs".to_owned(), code);

    for k in kernels {
        let mut code = String::new();
        let used: Vec<&str> = k.structs.iter().filter(|s| structs.get(&s.name).is_some_and(StructInfo::mirrorable)).map(|s| s.name.as_str()).collect();
        if !used.is_empty() {
            writeln!(code, "pub use crate::kernels::gpu_data::{{{}}};", used.join(", ")).unwrap();
        }
        writeln!(code, "/// `@workgroup_size` of `{}`.", k.name).unwrap();
        writeln!(code, "pub const WORKGROUP_SIZE: [u32; 3] = {:?};", k.workgroup_size).unwrap();
        writeln!(code, "/// Resources of one `{}` dispatch, in WGSL binding order.", k.name).unwrap();
        writeln!(code, "#[derive(Clone, Copy, Debug)]").unwrap();
        writeln!(code, "pub struct Bindings<'a> {{").unwrap();
        for b in &k.bindings {
            let access = match b.kind.as_str() {
                "Uniform" => "uniform".to_owned(),
                "StorageRead" => "storage, read".to_owned(),
                "StorageReadWrite" => "storage, read_write".to_owned(),
                other => other.split(' ').next().unwrap_or("").to_lowercase(),
            };
            let doc = if b.doc.is_empty() { String::new() } else { format!(": {}", doc_line(&b.doc)) };
            writeln!(code, "    /// Binding {} (`{access}`, `{}`){doc}", b.binding, b.wgsl_type).unwrap();
            let ty = match b.resource {
                "buffer" => "&'a wgpu::Buffer",
                "texture" => "&'a wgpu::TextureView",
                _ => "&'a wgpu::Sampler",
            };
            writeln!(code, "    pub {}: {ty},", b.name).unwrap();
        }
        writeln!(code, "}}").unwrap();
        writeln!(code, "impl Bindings<'_> {{").unwrap();
        writeln!(code, "    /// The bind group of these resources, labelled `core.{}.bind_group`.", k.name).unwrap();
        writeln!(code, "    pub fn bind_group(&self, gpu: &crate::Gpu) -> wgpu::BindGroup {{").unwrap();
        writeln!(code, "        gpu.kernels.{}.bind_group(&gpu.device, &[", k.name).unwrap();
        for b in &k.bindings {
            let resource = match b.resource {
                "buffer" => format!("self.{}.as_entire_binding()", b.name),
                "texture" => format!("wgpu::BindingResource::TextureView(self.{})", b.name),
                _ => format!("wgpu::BindingResource::Sampler(self.{})", b.name),
            };
            writeln!(code, "            wgpu::BindGroupEntry {{ binding: {}, resource: {resource} }},", b.binding).unwrap();
        }
        writeln!(code, "        ])\n    }}\n}}").unwrap();
        writeln!(code, "/// Bind group layout entries of `{}`, from its reflected bindings.", k.name).unwrap();
        writeln!(code, "pub fn layout_entries() -> Vec<wgpu::BindGroupLayoutEntry> {{\n    vec![").unwrap();
        for b in &k.bindings {
            writeln!(code, "        wgpu::BindGroupLayoutEntry {{ binding: {}, visibility: wgpu::ShaderStages::COMPUTE, ty: {}, count: None }},", b.binding, b.layout).unwrap();
        }
        writeln!(code, "    ]\n}}").unwrap();
        writeln!(code, "/// The compiled `{}` pipeline of `gpu`.", k.name).unwrap();
        writeln!(code, "pub fn pipeline(gpu: &crate::Gpu) -> &crate::kernels::KernelPipeline {{\n    &gpu.kernels.{}\n}}", k.name).unwrap();
        writeln!(code, "/// The reflected kernel.").unwrap();
        writeln!(code, "pub const KERNEL: &webfusion_shaders::Kernel = &webfusion_shaders::{};", k.name.to_uppercase()).unwrap();
        write(format!("{}.rs", k.name), code);
    }

    let mut code = String::new();
    writeln!(code, "/// Every kernel's pipeline, compiled once per device: natively all at start-up, in parallel;").unwrap();
    writeln!(code, "/// in the browser each on first use, the rest by `compile_deferred`.").unwrap();
    writeln!(code, "#[derive(Debug)]\npub struct Kernels {{").unwrap();
    for k in kernels {
        writeln!(code, "    /// `{}` ({}): {}", k.name, k.capability, doc_line(&k.summary)).unwrap();
        writeln!(code, "    pub {}: DeferredPipeline,", k.name).unwrap();
    }
    writeln!(code, "}}").unwrap();
    writeln!(code, "impl Kernels {{").unwrap();
    writeln!(code, "    /// The kernels of `device`: natively compiled at once; in the browser on first use.").unwrap();
    writeln!(code, "    pub fn new(device: &wgpu::Device) -> Self {{").unwrap();
    writeln!(code, "        let specs: Vec<KernelSpec> = vec![").unwrap();
    for k in kernels {
        writeln!(code, "            (&webfusion_shaders::{}, {}::{}::layout_entries),", k.name.to_uppercase(), k.capability, k.name).unwrap();
    }
    writeln!(code, "        ];").unwrap();
    writeln!(code, "        let mut compiled = compile_eager(device, &specs).into_iter();").unwrap();
    writeln!(code, "        Self {{").unwrap();
    for (i, k) in kernels.iter().enumerate() {
        writeln!(code, "            {}: DeferredPipeline::new(device, specs[{i}], compiled.next().flatten()),", k.name).unwrap();
    }
    writeln!(code, "        }}\n    }}").unwrap();
    writeln!(code, "    /// Compiles the pipelines that are not yet (the browser calls this once the first frame").unwrap();
    writeln!(code, "    /// is fused).").unwrap();
    writeln!(code, "    pub fn compile_deferred(&self) {{").unwrap();
    for k in kernels {
        writeln!(code, "        let _: &KernelPipeline = &self.{};", k.name).unwrap();
    }
    writeln!(code, "    }}").unwrap();
    writeln!(code, "    /// Whether every pipeline is compiled.").unwrap();
    let all_compiled: Vec<String> = kernels.iter().map(|k| format!("self.{}.is_compiled()", k.name)).collect();
    writeln!(code, "    pub fn all_compiled(&self) -> bool {{\n        {}\n    }}", all_compiled.join(" && ")).unwrap();
    writeln!(code, "    /// How many kernels there are.").unwrap();
    writeln!(code, "    pub const COUNT: usize = {};", kernels.len()).unwrap();
    writeln!(code, "    /// How many pipelines are compiled so far.").unwrap();
    writeln!(code, "    pub fn compiled_count(&self) -> usize {{\n        [{}].iter().filter(|&&c| c).count()\n    }}", all_compiled.join(", ")).unwrap();
    writeln!(code, "    /// Every pipeline, in `webfusion_shaders::ALL` order (compiling deferred ones).").unwrap();
    writeln!(code, "    pub fn all(&self) -> Vec<&KernelPipeline> {{\n        vec![{}]\n    }}", kernels.iter().map(|k| format!("&*self.{}", k.name)).collect::<Vec<_>>().join(", ")).unwrap();
    writeln!(code, "}}").unwrap();
    write("kernels_struct.rs".to_owned(), code);
}

fn layout_checks_code(kernels: &[KernelInfo], structs: &BTreeMap<String, StructInfo>) -> String {
    let mut code = String::new();
    writeln!(code, "/// Every generated `gpu_data` mirror has naga's size and member offsets (a check of the").unwrap();
    writeln!(code, "/// generator: the mirrors are written from the same reflection).").unwrap();
    writeln!(code, "#[test]\nfn generated_mirrors_match_naga_layouts() {{").unwrap();
    for s in structs.values().filter(|s| s.mirrorable()) {
        let kernel = kernels.iter().find(|k| k.structs.iter().any(|t| t.name == s.name)).expect("a struct comes from a kernel");
        let fields: Vec<&str> = s.members.iter().map(|m| m.name.as_str()).collect();
        writeln!(
            code,
            "    check_layout!(webfusion_shaders::{}, {:?}, webfusion_core::kernels::gpu_data::{}, [{}]);",
            kernel.name.to_uppercase(),
            s.name,
            s.name,
            fields.join(", ")
        )
        .unwrap();
    }
    writeln!(code, "}}").unwrap();
    code
}

fn manifest(kernels: &[KernelInfo]) -> String {
    kernels.iter().map(|k| format!("{}\t{}\t{}\n", k.capability, k.name, k.summary.replace('\t', " "))).collect()
}
