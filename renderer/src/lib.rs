//! The `vkterrain` renderer: Vulkan context, frame loop, culling, LOD, stitching and the frame-timing log. Filled by the renderer issue.
