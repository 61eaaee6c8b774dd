# The include-level half of the dependency rule (docs/architecture.md); the link-level half
# runs at configure time (cmake/TesseraTargets.cmake).
#   cmake -DSOURCE_DIR=<tree> -P tests/dependency_rule.cmake
# Every #include <tessera/...> of a source file must name a header owned by a layer that file
# may use:
#   base          -> base
#   messages      -> base, messages
#   runtime       -> base, messages, runtime
#   hw core       -> base, hw core                 (hw/datasets, hw/sim without actor/)
#   hw actors     -> base, messages, runtime, hw core, their own folder
#   actors core   -> base, actors core             (actors/<domain> without actor/)
#   actors common -> base, messages, runtime, actors core, itself (actors/common: glue)
#   actors actors -> base, messages, runtime, actors core, actors common, their own folder
# apps/ and tests/ may include anything, except that apps/ outside apps/bench never includes
# iceoryx. Cap'n Proto (<capnp/..>, <kj/..>) counts as messages.
cmake_minimum_required(VERSION 3.22)
if(NOT SOURCE_DIR)
  message(FATAL_ERROR "usage: cmake -DSOURCE_DIR=<tree> -P dependency_rule.cmake")
endif()

# Layer of a folder (relative path of a file or of an include directory).
function(layer_of rel out)
  if(rel MATCHES "^base/")
    set(l base)
  elseif(rel MATCHES "^messages/")
    set(l messages)
  elseif(rel MATCHES "^runtime/")
    set(l runtime)
  elseif(rel MATCHES "^hw/[a-z0-9_]+/actor/" OR rel MATCHES "^hw/players/")
    set(l hw_actor)
  elseif(rel MATCHES "^hw/")
    set(l hw_core)
  elseif(rel MATCHES "^actors/common/")
    set(l actor_common)
  elseif(rel MATCHES "^actors/[a-z0-9_]+/actor/")
    set(l actor)
  elseif(rel MATCHES "^actors/")
    set(l core)
  else()
    set(l other)
  endif()
  set(${out} ${l} PARENT_SCOPE)
endfunction()

# Actor folders own their files: hw/sim/actor, hw/players, actors/<domain>/actor.
function(actor_folder_of rel out)
  string(REGEX MATCH "^(actors/[a-z0-9_]+/actor|hw/[a-z0-9_]+/actor|hw/players)/" m "${rel}")
  set(${out} "${CMAKE_MATCH_1}" PARENT_SCOPE)
endfunction()

set(allowed_base base)
set(allowed_messages base messages)
set(allowed_runtime base messages runtime)
set(allowed_hw_core base hw_core)
set(allowed_hw_actor base messages runtime hw_core hw_actor)
set(allowed_core base core)
set(allowed_actor_common base messages runtime core actor_common)
set(allowed_actor base messages runtime core actor_common actor)

# Owner of every public header: tessera/x/y.hpp -> the folder whose include/ holds it.
file(GLOB_RECURSE headers RELATIVE ${SOURCE_DIR}
  ${SOURCE_DIR}/base/*.hpp ${SOURCE_DIR}/messages/*.hpp ${SOURCE_DIR}/runtime/*.hpp
  ${SOURCE_DIR}/hw/*.hpp ${SOURCE_DIR}/actors/*.hpp)
foreach(h IN LISTS headers)
  if(h MATCHES "/include/(tessera/.*)$")
    set(owner_${CMAKE_MATCH_1} ${h})
  endif()
endforeach()

file(GLOB_RECURSE sources RELATIVE ${SOURCE_DIR}
  ${SOURCE_DIR}/base/*.[hc]pp ${SOURCE_DIR}/messages/*.[hc]pp ${SOURCE_DIR}/runtime/*.[hc]pp
  ${SOURCE_DIR}/hw/*.[hc]pp ${SOURCE_DIR}/actors/*.[hc]pp)
set(errors "")
set(checked 0)
foreach(src IN LISTS sources)
  layer_of(${src} layer)
  actor_folder_of(${src} src_actor_folder)
  file(STRINGS ${SOURCE_DIR}/${src} includes REGEX "^#include <(tessera|capnp|kj)/")
  foreach(inc IN LISTS includes)
    string(REGEX REPLACE "^#include <([^>]+)>.*$" "\\1" path "${inc}")
    math(EXPR checked "${checked} + 1")
    if(path MATCHES "^(capnp|kj)/" OR path MATCHES "^tessera/msg/")
      set(target_layer messages)
      set(target_rel "messages/")
    elseif(DEFINED owner_${path})
      set(target_rel ${owner_${path}})
      layer_of(${target_rel} target_layer)
    else()
      string(APPEND errors "\n  ${src}: includes <${path}>, which no include/ folder holds")
      continue()
    endif()
    if(NOT target_layer IN_LIST allowed_${layer})
      string(APPEND errors "\n  ${src} (${layer}) includes <${path}> (${target_layer}: ${target_rel})")
    elseif(target_layer MATCHES "actor$")
      actor_folder_of(${target_rel} target_actor_folder)
      if(NOT target_actor_folder STREQUAL src_actor_folder)
        string(APPEND errors
          "\n  ${src} includes <${path}> from another actor library (${target_actor_folder})")
      endif()
    endif()
  endforeach()
endforeach()

# The product commands (apps/, not apps/bench) reach shared memory through tessera_shm only; the
# benchmarks in apps/bench may use iceoryx directly.
file(GLOB app_sources RELATIVE ${SOURCE_DIR} ${SOURCE_DIR}/apps/*.[hc]pp)
foreach(src IN LISTS app_sources)
  file(STRINGS ${SOURCE_DIR}/${src} includes REGEX "^#include <iceoryx")
  foreach(inc IN LISTS includes)
    string(APPEND errors "\n  ${src} (apps) includes iceoryx directly: ${inc}")
  endforeach()
endforeach()

list(LENGTH sources n_sources)
if(errors)
  message(FATAL_ERROR "Dependency rule broken (docs/architecture.md):${errors}")
endif()
message(STATUS "dependency rule: ${checked} includes in ${n_sources} files follow the layers")
