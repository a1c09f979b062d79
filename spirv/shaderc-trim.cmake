# Included after each project() of shaderc's build (CMAKE_PROJECT_INCLUDE, set by
# shaderc.cmake). At the end of the top-level directory, once every target exists, it takes out
# of the default build what shaderc-sys never links: it links libshaderc_combined.a alone
# (shaderc, glslang, SPIRV-Tools and its optimiser), so SPIRV-Tools' shared copy of itself and
# its reducer, linter, differ and linker were compiled for nothing. Their install rules are
# skipped with them (SKIP_SPIRV_TOOLS_INSTALL in shaderc.cmake).
get_property(vkterrain_trim_deferred GLOBAL PROPERTY VKTERRAIN_SHADERC_TRIM)
if(NOT vkterrain_trim_deferred)
  set_property(GLOBAL PROPERTY VKTERRAIN_SHADERC_TRIM ON)
  function(vkterrain_shaderc_trim)
    foreach(unused IN ITEMS SPIRV-Tools-shared SPIRV-Tools-reduce SPIRV-Tools-lint
                            SPIRV-Tools-diff SPIRV-Tools-link)
      if(TARGET ${unused})
        set_target_properties(${unused} PROPERTIES EXCLUDE_FROM_ALL TRUE)
      endif()
    endforeach()
  endfunction()
  cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL vkterrain_shaderc_trim)
endif()
