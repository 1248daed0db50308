# terrain_library(NAME DIR DESCRIPTION): one pipeline stage as a CMake target `NAME` (alias
# terrain::NAME) built from DIR/src/*.cpp, with public headers in DIR/include/NAME/ and private
# ones in DIR/include/NAME/internal/ (visible to tests, not installed), as zfp lays out its tree.
function(terrain_library name dir)
  file(GLOB sources CONFIGURE_DEPENDS ${dir}/src/*.cpp)
  add_library(${name} ${sources} ${ARGN})
  target_include_directories(${name} PUBLIC $<BUILD_INTERFACE:${dir}/include>
                                            $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}> PRIVATE ${dir}/src)
  add_library(terrain::${name} ALIAS ${name})
  install(TARGETS ${name} EXPORT terrainTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
          LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(DIRECTORY ${dir}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} PATTERN internal EXCLUDE)
endfunction()
