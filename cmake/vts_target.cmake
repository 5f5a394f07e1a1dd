# One place that configures every vtstream target the same way: language level, warnings and
# sanitizers. Call vts_configure_target(<target>) right after add_library/add_executable.
function(vts_configure_target target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  set_target_properties(${target} PROPERTIES CXX_EXTENSIONS OFF)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wshadow -Wnon-virtual-dtor
                                           -Wno-missing-field-initializers)
  if(VTS_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# Applied globally (before any target) when VTS_SANITIZE is on, so that every library and test
# in the tree is instrumented consistently.
macro(vts_enable_sanitizers)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endmacro()
