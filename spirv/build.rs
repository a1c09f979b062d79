//! Compiles the GLSL in `shaders/` to SPIR-V with shaderc and writes the words as Rust
//! constants, so the renderer embeds them and no shader compiler is needed at run time.

use std::fmt::Write as _;
use std::path::PathBuf;

/// (constant, file, stage, macro defined for this build).
const SHADERS: [(&str, &str, shaderc::ShaderKind, Option<&str>); 5] = [
    (
        "TERRAIN_VERT",
        "terrain.vert",
        shaderc::ShaderKind::Vertex,
        None,
    ),
    (
        "TERRAIN_VERT_BRANCHES",
        "terrain.vert",
        shaderc::ShaderKind::Vertex,
        Some("MORPH_BRANCHES"),
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
        "INDICES_COMP",
        "indices.comp",
        shaderc::ShaderKind::Compute,
        None,
    ),
];

fn main() {
    let dir =
        PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it")).join("shaders");
    let compiler = shaderc::Compiler::new().expect("shaderc initialises");
    let mut out = String::new();
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
        let path = dir.join(file);
        println!("cargo:rerun-if-changed={}", path.display());
        let source =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let binary = compiler
            .compile_into_spirv(&source, kind, file, "main", Some(&options))
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        let words = binary.as_binary();
        let _ = writeln!(
            out,
            "/// SPIR-V of `shaders/{file}`{}.\npub const {name}: &[u32] = &{words:?};",
            define.map_or(String::new(), |d| format!(" with `{d}` defined"))
        );
    }
    let dest = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets it")).join("shaders.rs");
    std::fs::write(&dest, out).unwrap_or_else(|e| panic!("{}: {e}", dest.display()));
}
