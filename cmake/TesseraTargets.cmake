# Target kinds of the tree and the dependency rule between them (docs/architecture.md).
#
#   tessera_core_library(NAME src...)   plain C++ over Eigen/TBB/Ceres: never the runtime,
#                                       messages or Cap'n Proto
#   tessera_actor_library(NAME src...)  thin adapters from messages to one domain's core; actors
#                                       register themselves, so executables link them whole
#
# tessera_check_dependency_rule() runs at the end of configure and fails it when a core library
# reaches the runtime or messages through its links, when an actor library links another
# domain's actor library, when a hw/ target links a library from actors/, or when the `tessera`
# CLI links iceoryx directly instead of through tessera_shm or tessera_bench. The include-level
# half of the rule is the `dependency_rule` test (tests/dependency_rule.cmake).

function(tessera_core_library name)
  add_library(${name} STATIC ${ARGN})
  set_property(GLOBAL APPEND PROPERTY TESSERA_CORE_TARGETS ${name})
  set_property(TARGET ${name} PROPERTY TESSERA_SOURCE_FOLDER ${CMAKE_CURRENT_SOURCE_DIR})
endfunction()

function(tessera_actor_library name)
  add_library(${name} STATIC ${ARGN})
  set_property(GLOBAL APPEND PROPERTY TESSERA_ACTOR_TARGETS ${name})
  set_property(TARGET ${name} PROPERTY TESSERA_SOURCE_FOLDER ${CMAKE_CURRENT_SOURCE_DIR})
endfunction()

# Every tessera_* target `target` links, directly or through other tessera_* targets.
function(_tessera_link_closure target out)
  set(seen "")
  set(todo ${target})
  while(todo)
    list(POP_FRONT todo t)
    foreach(prop LINK_LIBRARIES INTERFACE_LINK_LIBRARIES)
      get_target_property(libs ${t} ${prop})
      if(NOT libs)
        continue()
      endif()
      foreach(lib IN LISTS libs)
        # $<LINK_ONLY:x> and $<LINK_LIBRARY:WHOLE_ARCHIVE,x,...> name targets inside a genex.
        string(REGEX REPLACE "^\\$<LINK_ONLY:(.*)>$" "\\1" lib "${lib}")
        if(lib MATCHES "^tessera_" AND TARGET ${lib} AND NOT lib IN_LIST seen)
          list(APPEND seen ${lib})
          list(APPEND todo ${lib})
        elseif(lib MATCHES "^CapnProto::")
          list(APPEND seen ${lib})
        endif()
      endforeach()
    endforeach()
  endwhile()
  set(${out} ${seen} PARENT_SCOPE)
endfunction()

function(tessera_check_dependency_rule)
  get_property(cores GLOBAL PROPERTY TESSERA_CORE_TARGETS)
  get_property(actors GLOBAL PROPERTY TESSERA_ACTOR_TARGETS)
  set(errors "")
  foreach(core IN LISTS cores)
    _tessera_link_closure(${core} deps)
    foreach(bad tessera_runtime tessera_messages tessera_shm CapnProto::capnp CapnProto::kj)
      if(bad IN_LIST deps)
        string(APPEND errors "\n  core library ${core} links ${bad}")
      endif()
    endforeach()
    foreach(actor IN LISTS actors)
      if(actor IN_LIST deps)
        string(APPEND errors "\n  core library ${core} links actor library ${actor}")
      endif()
    endforeach()
  endforeach()
  foreach(actor IN LISTS actors)
    _tessera_link_closure(${actor} deps)
    foreach(other IN LISTS actors)
      if(NOT other STREQUAL actor AND other IN_LIST deps)
        string(APPEND errors "\n  actor library ${actor} links another actor library, ${other}")
      endif()
    endforeach()
  endforeach()
  foreach(t IN LISTS cores actors)
    get_target_property(folder ${t} TESSERA_SOURCE_FOLDER)
    if(folder MATCHES "/hw/")
      _tessera_link_closure(${t} deps)
      foreach(dep IN LISTS deps)
        if(TARGET ${dep})
          get_target_property(dep_folder ${dep} TESSERA_SOURCE_FOLDER)
          if(dep_folder MATCHES "/actors/")
            string(APPEND errors "\n  hw library ${t} links ${dep} from actors/")
          endif()
        endif()
      endforeach()
    endif()
  endforeach()
  # The product CLI reaches shared memory through tessera_shm; only its benchmarks
  # (tessera_bench) link iceoryx themselves.
  foreach(app tessera tessera_cli_common)
    if(TARGET ${app})
      get_target_property(app_libs ${app} LINK_LIBRARIES)
      foreach(lib IN LISTS app_libs)
        if(lib MATCHES "iceoryx")
          string(APPEND errors "\n  ${app} links ${lib} directly (only tessera_bench may)")
        endif()
      endforeach()
    endif()
  endforeach()
  if(errors)
    message(FATAL_ERROR "Dependency rule broken (docs/architecture.md):${errors}")
  endif()
  list(LENGTH cores n_cores)
  list(LENGTH actors n_actors)
  message(STATUS "Dependency rule: ${n_cores} core and ${n_actors} actor libraries checked")
endfunction()

# Unity builds (CMAKE_UNITY_BUILD=ON, as scripts/build.sh and scripts/sanitize.sh configure a
# fresh tree: a cold build parses the heavy headers once per batch instead of once per file).
# Files whose file-local helpers (anonymous namespace) share a name with another file's of the same
# target, or that hold file-local types in a class's members, are compiled on their own:
#   tessera_own_translation_units(file...)   paths relative to the calling CMakeLists.txt
function(tessera_own_translation_units)
  set_source_files_properties(${ARGN} PROPERTIES SKIP_UNITY_BUILD_INCLUSION ON)
endfunction()
