cmake_minimum_required(VERSION 3.22)
# Stage an install of the build tree, then configure, build and run an outside project that
# finds it with find_package(stiff CONFIG) - what a user of the installed library does.
#   -DSOURCE, -DBUILD: this project; -DWORK: scratch folder; -DPROJECT_DIR: the outside project
#   -DPREPARE: optional command run first (';'-list); -DRUN: the command to run (';'-list, may
#   use <WORK> and <PREFIX>); -DEXPECT: a regular expression its output must match.
file(REMOVE_RECURSE ${WORK})
set(PREFIX ${WORK}/prefix)
function(run_or_fail what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${out}${err}")
  endif()
  set(last_output "${out}" PARENT_SCOPE)
endfunction()
run_or_fail("install" ${CMAKE_COMMAND} --install ${BUILD} --prefix ${PREFIX})
run_or_fail("configure of ${PROJECT_DIR}" ${CMAKE_COMMAND} -S ${PROJECT_DIR} -B ${WORK}/build -G Ninja
            -DCMAKE_PREFIX_PATH=${PREFIX})
run_or_fail("build of ${PROJECT_DIR}" ${CMAKE_COMMAND} --build ${WORK}/build)
foreach(step PREPARE RUN)
  if(${step})
    string(REPLACE "<WORK>" "${WORK}" cmd "${${step}}")
    string(REPLACE "<PREFIX>" "${PREFIX}" cmd "${cmd}")
    run_or_fail("${step} (${cmd})" ${cmd})
  endif()
endforeach()
message("${last_output}")
if(EXPECT AND NOT last_output MATCHES "${EXPECT}")
  message(FATAL_ERROR "output does not match '${EXPECT}'")
endif()
