# CMake toolchain file for shaderc's build from source (glslang, SPIRV-Tools), named by
# .cargo/config.toml. shaderc runs only at build time, compiling the renderer's few shaders in
# a second either way, so its C++ is compiled without optimisation: optimising it was most of a
# fresh build's time on a two-core machine (shaderc-sys asks CMake for a Release build, -O3).
# Set in the cache, as the command line would: CMake appends its -O3 to the *_INIT flags.
set(CMAKE_C_FLAGS_RELEASE "-DNDEBUG" CACHE STRING "shaderc is a build-time tool: no -O3")
set(CMAKE_CXX_FLAGS_RELEASE "-DNDEBUG" CACHE STRING "shaderc is a build-time tool: no -O3")
# What shaderc-sys does not link is not built (see shaderc-trim.cmake): no SPIRV-Tools install
# (its shared library and tools), no examples. (glslc stays: shaderc installs it.)
set(SHADERC_SKIP_EXAMPLES ON CACHE BOOL "shaderc-sys links the library alone")
set(SKIP_SPIRV_TOOLS_INSTALL ON CACHE BOOL "shaderc-sys links libshaderc_combined.a alone")
set(CMAKE_PROJECT_INCLUDE "${CMAKE_CURRENT_LIST_DIR}/shaderc-trim.cmake")
