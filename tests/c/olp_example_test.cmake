# Build examples/olp_c against a staged install with its own CMake and run it on the example
# contour path with a fit identified by the build's own tools.
file(REMOVE_RECURSE ${WORK})
execute_process(COMMAND ${CMAKE_COMMAND} --install ${BUILD} --prefix ${WORK}/prefix
                RESULT_VARIABLE rc OUTPUT_QUIET)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "install failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} -S ${SOURCE}/examples/olp_c -B ${WORK}/build -G Ninja
                -DCMAKE_PREFIX_PATH=${WORK}/prefix RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "configure of examples/olp_c failed")
endif()
execute_process(COMMAND ${CMAKE_COMMAND} --build ${WORK}/build RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "build of examples/olp_c failed")
endif()
# A fit: the usage test writes one (joint model of the paper's design) next to it.
execute_process(COMMAND ${USAGE} ${SOURCE} ${WORK}/fit.json RESULT_VARIABLE rc OUTPUT_QUIET)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "could not create a fit")
endif()
execute_process(COMMAND ${WORK}/build/olp_compensate ${SOURCE}/examples/robots/rokae.yaml
                ${WORK}/fit.json ${SOURCE}/examples/paths/rokae_contour.csv ${WORK}/out.csv
                RESULT_VARIABLE rc OUTPUT_VARIABLE out)
message("${out}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "olp_compensate failed")
endif()
file(STRINGS ${WORK}/out.csv lines)
list(LENGTH lines n)
if(NOT n EQUAL 336)
  message(FATAL_ERROR "expected 335 points and a header, got ${n} lines")
endif()
if(NOT out MATCHES "compensated 335 points \\(0 with problems\\)")
  message(FATAL_ERROR "unexpected output: ${out}")
endif()
