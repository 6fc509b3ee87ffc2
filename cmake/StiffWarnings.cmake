# Warning flags and floating-point policy shared by every target.
function(stiff_target_defaults target)
  target_compile_options(${target} PRIVATE
    $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wshadow>
    $<$<COMPILE_LANGUAGE:C>:-Wall -Wextra -Wpedantic>
    -ffp-contract=off)
  if(STIFF_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(STIFF_SANITIZE)
    string(REPLACE ";" "," _san "${STIFF_SANITIZE}")
    target_compile_options(${target} PRIVATE -fsanitize=${_san} -fno-omit-frame-pointer)
    target_link_options(${target} PRIVATE -fsanitize=${_san})
  endif()
endfunction()
