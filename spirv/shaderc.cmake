# CMake toolchain file for shaderc's build from source (glslang, SPIRV-Tools), named by
# .cargo/config.toml. shaderc runs only at build time, compiling the renderer's few shaders in
# a second either way, so its C++ is compiled without optimisation: optimising it was most of a
# fresh build's time on a two-core machine (shaderc-sys asks CMake for a Release build, -O3).
# Set in the cache, as the command line would: CMake appends its -O3 to the *_INIT flags.
set(CMAKE_C_FLAGS_RELEASE "-DNDEBUG" CACHE STRING "shaderc is a build-time tool: no -O3")
set(CMAKE_CXX_FLAGS_RELEASE "-DNDEBUG" CACHE STRING "shaderc is a build-time tool: no -O3")
