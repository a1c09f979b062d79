//! GLSL shader sources and their SPIR-V, compiled by shaderc at build time and exposed as `&[u32]` words. Filled by the renderer issue.
