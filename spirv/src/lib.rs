//! The renderer's shaders: GLSL in `shaders/`, compiled to SPIR-V by shaderc when this crate
//! builds, exposed as `&[u32]` words ready for `vkCreateShaderModule`.
//!
//! ```
//! assert_eq!(spirv::TERRAIN_VERT[0], 0x0723_0203); // the SPIR-V magic number
//! ```

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
