//! Compiles the GLSL in `shaders/` to SPIR-V with shaderc and writes the words as Rust
//! constants, so the renderer embeds them and no shader compiler is needed at run time.
//!
//! The terrain shaders share one interface file (`shaders/interface.glsl`, pulled in by
//! shaderc's include callback). Two things are read back out of it for the host: its flag
//! constants (`const uint NAME = VALUEu;` lines) become Rust constants in [`flags`], and the
//! member offsets the compiler gave its structs (the SPIR-V's `Offset` and `ArrayStride`
//! decorations) become [`TERRAIN_LAYOUT`], which the renderer's tests compare with its
//! `#[repr(C)]` mirror field by field.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// (constant, file, stage, macro defined for this build).
const SHADERS: [(&str, &str, shaderc::ShaderKind, Option<&str>); 11] = [
    (
        "TERRAIN_VERT",
        "terrain.vert",
        shaderc::ShaderKind::Vertex,
        None,
    ),
    (
        "TERRAIN_VERT_TWO_LEVELS",
        "terrain.vert",
        shaderc::ShaderKind::Vertex,
        Some("TWO_LEVELS"),
    ),
    (
        "TERRAIN_VERT_ALL_ROWS",
        "terrain.vert",
        shaderc::ShaderKind::Vertex,
        Some("MORPH_ALL_ROWS"),
    ),
    (
        "TERRAIN_VERT_READ_BACK",
        "terrain.vert",
        shaderc::ShaderKind::Vertex,
        Some("READ_BACK"),
    ),
    (
        "TERRAIN_FRAG",
        "terrain.frag",
        shaderc::ShaderKind::Fragment,
        None,
    ),
    (
        "TERRAIN_FRAG_MIN_LOD",
        "terrain.frag",
        shaderc::ShaderKind::Fragment,
        Some("MIN_LOD"),
    ),
    (
        "LIMIT_VERT",
        "limit.vert",
        shaderc::ShaderKind::Vertex,
        None,
    ),
    (
        "LIMIT_FRAG",
        "limit.frag",
        shaderc::ShaderKind::Fragment,
        None,
    ),
    (
        "MORPH_COMP",
        "morph.comp",
        shaderc::ShaderKind::Compute,
        None,
    ),
    (
        "INDICES_COMP",
        "indices.comp",
        shaderc::ShaderKind::Compute,
        None,
    ),
    (
        "DECODE_COMP",
        "decode.comp",
        shaderc::ShaderKind::Compute,
        None,
    ),
];

/// The shared interface, and the structs of it whose layout the host mirrors.
const INTERFACE: &str = "interface.glsl";
const MIRRORED: [&str; 5] = [
    "FrameConstants",
    "LevelCoefficients",
    "MorphFrame",
    "Records",
    "TileRecord",
];

fn main() {
    let dir =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it")).join("shaders");
    let compiler = shaderc::Compiler::new().expect("shaderc initialises");
    let mut out = String::new();
    for include in [INTERFACE, "parts.glsl", "hierarchy.glsl"] {
        println!("cargo:rerun-if-changed={}", dir.join(include).display());
    }
    let mut layout = None;
    for (name, file, kind, define) in SHADERS {
        let mut options = shaderc::CompileOptions::new().expect("shaderc options");
        options.set_target_env(
            shaderc::TargetEnv::Vulkan,
            shaderc::EnvVersion::Vulkan1_2 as u32,
        );
        options.set_optimization_level(shaderc::OptimizationLevel::Performance);
        options.set_warnings_as_errors();
        if let Some(d) = define {
            options.add_macro_definition(d, None);
        }
        let include_dir = dir.clone();
        options.set_include_callback(move |requested, _, _, _| {
            let path = include_dir.join(requested);
            let content =
                std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(shaderc::ResolvedInclude {
                resolved_name: path.display().to_string(),
                content,
            })
        });
        let path = dir.join(file);
        println!("cargo:rerun-if-changed={}", path.display());
        let source =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let binary = compiler
            .compile_into_spirv(&source, kind, file, "main", Some(&options))
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        let words = binary.as_binary();
        if name == "TERRAIN_VERT" {
            // The layout from an unoptimised build: the optimiser may drop names (never
            // offsets, which it must keep as they are).
            options.set_optimization_level(shaderc::OptimizationLevel::Zero);
            let plain = compiler
                .compile_into_spirv(&source, kind, file, "main", Some(&options))
                .unwrap_or_else(|e| panic!("{file}: {e}"));
            layout = Some(struct_layout(plain.as_binary(), &MIRRORED));
        }
        let _ = writeln!(
            out,
            "/// SPIR-V of `shaders/{file}`{}.\npub const {name}: &[u32] = &{words:?};",
            define.map_or(String::new(), |d| format!(" with `{d}` defined"))
        );
    }
    let layout = layout.expect("the terrain vertex shader compiles");
    for s in MIRRORED {
        assert!(
            layout.iter().any(|(name, _, _)| name == s),
            "{INTERFACE}: struct {s} has no layout in terrain.vert (are its names stripped?)"
        );
    }
    let _ = writeln!(
        out,
        "/// `(struct, member, byte offset)` of the structs of `shaders/{INTERFACE}` as compiled \
         into `terrain.vert`; member `\"stride\"` is the array stride where the struct is an \
         array's element.\npub const TERRAIN_LAYOUT: &[(&str, &str, u32)] = &{layout:?};"
    );
    let _ = writeln!(
        out,
        "/// The flag constants of `shaders/{INTERFACE}`.\npub mod flags {{"
    );
    for (name, value) in flag_constants(&dir.join(INTERFACE)) {
        let _ = writeln!(out, "    pub const {name}: u32 = {value};");
    }
    let _ = writeln!(out, "}}");
    let dest = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets it")).join("shaders.rs");
    std::fs::write(&dest, out).unwrap_or_else(|e| panic!("{}: {e}", dest.display()));
}

/// The `const uint NAME = VALUEu;` lines of `path`.
fn flag_constants(path: &Path) -> Vec<(String, u32)> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .filter_map(|line| {
            let rest = line.trim().strip_prefix("const uint ")?;
            let (name, value) = rest.split_once('=')?;
            let value = value.trim().split(';').next()?.trim().strip_suffix('u')?;
            let value = value.parse().unwrap_or_else(|e| panic!("{line}: {e}"));
            Some((name.trim().to_string(), value))
        })
        .collect()
}

/// `(struct, member, offset)` for every member of the named structs in a SPIR-V module, and
/// `(struct, "stride", n)` where an array of the struct is decorated with a stride.
fn struct_layout(words: &[u32], names: &[&str]) -> Vec<(String, String, u32)> {
    const OP_NAME: u32 = 5;
    const OP_MEMBER_NAME: u32 = 6;
    const OP_TYPE_ARRAY: u32 = 28;
    const OP_TYPE_RUNTIME_ARRAY: u32 = 29;
    const OP_DECORATE: u32 = 71;
    const OP_MEMBER_DECORATE: u32 = 72;
    const DECORATION_ARRAY_STRIDE: u32 = 6;
    const DECORATION_OFFSET: u32 = 35;
    let string = |w: &[u32]| {
        let bytes: Vec<u8> = w.iter().flat_map(|x| x.to_le_bytes()).collect();
        let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
        String::from_utf8_lossy(&bytes[..end]).into_owned()
    };
    let (mut type_names, mut member_names) = (HashMap::new(), HashMap::new());
    let (mut offsets, mut strides, mut elements) = (Vec::new(), HashMap::new(), HashMap::new());
    let mut i = 5;
    while i < words.len() {
        let (count, op) = ((words[i] >> 16) as usize, words[i] & 0xffff);
        let w = &words[i + 1..i + count.max(1)];
        match op {
            OP_NAME => {
                type_names.insert(w[0], string(&w[1..]));
            }
            OP_MEMBER_NAME => {
                member_names.insert((w[0], w[1]), string(&w[2..]));
            }
            OP_MEMBER_DECORATE if w[2] == DECORATION_OFFSET => offsets.push((w[0], w[1], w[3])),
            OP_DECORATE if w[1] == DECORATION_ARRAY_STRIDE => {
                strides.insert(w[0], w[2]);
            }
            OP_TYPE_ARRAY | OP_TYPE_RUNTIME_ARRAY => {
                elements.insert(w[0], w[1]);
            }
            _ => {}
        }
        i += count.max(1);
    }
    let wanted = |id: &u32| {
        type_names
            .get(id)
            .filter(|n| names.contains(&n.as_str()))
            .cloned()
    };
    let mut layout: Vec<(String, String, u32)> = offsets
        .iter()
        .filter_map(|&(id, member, offset)| {
            let s = wanted(&id)?;
            let m = member_names.get(&(id, member)).cloned()?;
            Some((s, m, offset))
        })
        .collect();
    for (array, element) in &elements {
        if let (Some(s), Some(&stride)) = (wanted(element), strides.get(array)) {
            layout.push((s, "stride".into(), stride));
        }
    }
    layout.sort();
    layout.dedup();
    layout
}
