# Compare the built libstiff_c with the committed ABI baseline (abi/libstiff_c.abi, written by
# `make abi-baseline`): fail on any incompatible change (abidiff exit bit 8). Additions are
# compatible. Without abidiff installed the check fails: it is part of the contract.
find_program(ABIDIFF abidiff)
if(NOT ABIDIFF)
  message(FATAL_ERROR "abidiff not found (Debian package abigail-tools)")
endif()
execute_process(COMMAND ${ABIDIFF} --headers-dir2 ${HEADERS} ${BASELINE} ${LIB}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
math(EXPR incompatible "${rc} & 8")
math(EXPR failed "${rc} & 3")
if(failed)
  message(FATAL_ERROR "abidiff could not compare (exit ${rc})")
endif()
if(incompatible)
  message(FATAL_ERROR "incompatible ABI change against ${BASELINE}: bump STIFF_ABI_VERSION and "
                      "regenerate the baseline (make abi-baseline), and say so in CHANGELOG.md")
endif()
