# Compare the built libstiff_c with the committed ABI baseline (abi/libstiff_c.abi, written by
# `make abi-baseline`). New functions pass; any other change - a removed or changed function,
# a changed type or layout - fails (abidiff exit bits 4 and 8). Appending a field to an option
# struct is compatible by the struct_size rule, but is reviewed: regenerate the baseline with
# `make abi-baseline` and note it under "ABI" in CHANGELOG.md. Without abidiff installed the
# check fails: it is part of the contract.
find_program(ABIDIFF abidiff)
if(NOT ABIDIFF)
  message(FATAL_ERROR "abidiff not found (Debian package abigail-tools)")
endif()
execute_process(COMMAND ${ABIDIFF} --exported-interfaces-only --no-added-syms
                        ${BASELINE} ${LIB}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
message("${out}${err}")
math(EXPR incompatible "${rc} & 12")
math(EXPR failed "${rc} & 3")
if(failed)
  message(FATAL_ERROR "abidiff could not compare (exit ${rc})")
endif()
if(incompatible)
  message(FATAL_ERROR "incompatible ABI change against ${BASELINE}: bump STIFF_ABI_VERSION and "
                      "regenerate the baseline (make abi-baseline), and say so in CHANGELOG.md")
endif()
