# Configures a game project that builds qgi with add_subdirectory, as README.md ("Using qgi in
# your engine") tells an engine to: the demo, tests and benchmarks off. It must configure
# without the demo's own libraries (CLI11) being asked for, leave the parent's empty build type
# alone, and offer the qgi::runtime and qgi::systems targets.
# Run as: cmake -DQGI_SOURCE=<repository> -DWORK=<scratch folder> -P embed_subproject.cmake
file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}/game")
file(WRITE "${WORK}/game/CMakeLists.txt" "
cmake_minimum_required(VERSION 3.25)
project(game CXX C)
set(QGI_BUILD_TESTS OFF CACHE BOOL \"\" FORCE)
set(QGI_BUILD_BENCHMARKS OFF CACHE BOOL \"\" FORCE)
set(QGI_BUILD_DEMO OFF CACHE BOOL \"\" FORCE)
add_subdirectory(\"${QGI_SOURCE}\" qgi)
foreach(target qgi::runtime qgi::systems)
    if(NOT TARGET \${target})
        message(FATAL_ERROR \"qgi as a subproject offers no \${target}\")
    endif()
endforeach()
file(WRITE \"\${CMAKE_BINARY_DIR}/build-type.txt\" \"[\${CMAKE_BUILD_TYPE}]\")
")
execute_process(COMMAND "${CMAKE_COMMAND}" -S "${WORK}/game" -B "${WORK}/build"
                RESULT_VARIABLE result OUTPUT_VARIABLE output ERROR_VARIABLE output)
if(NOT result EQUAL 0)
    message(FATAL_ERROR "qgi as a subproject does not configure:\n${output}")
endif()
file(READ "${WORK}/build/build-type.txt" buildType)
if(NOT buildType STREQUAL "[]")
    message(FATAL_ERROR "qgi as a subproject set the parent's build type to ${buildType}")
endif()
file(READ "${WORK}/build/CMakeCache.txt" cache)
if(cache MATCHES "CLI11_DIR:")
    message(FATAL_ERROR "qgi as a subproject looked for CLI11, which only the demo needs")
endif()
message(STATUS "qgi configures as a subproject")
