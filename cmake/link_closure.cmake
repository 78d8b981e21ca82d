# stereod_check_links_exclude(TARGET PATTERN WHY): stops the configuration when TARGET
# links, directly or through any library it links, a library whose name matches PATTERN
# (a regular expression). So that a layer the docs promise stays free of a dependency
# (docs/architecture.md, "What links what") cannot gain it by one include and one line
# of CMake unnoticed.
function(_stereod_link_closure target out)
  set(seen "")
  set(todo ${target})
  while(todo)
    list(POP_FRONT todo current)
    if(current IN_LIST seen)
      continue()
    endif()
    list(APPEND seen ${current})
    if(NOT TARGET ${current})
      continue()
    endif()
    get_target_property(links ${current} INTERFACE_LINK_LIBRARIES)
    if(NOT links)
      continue()
    endif()
    foreach(link IN LISTS links)
      # Static libraries carry their private links as $<LINK_ONLY:name>.
      string(REGEX REPLACE "^\\$<LINK_ONLY:(.*)>$" "\\1" link "${link}")
      list(APPEND todo ${link})
    endforeach()
  endwhile()
  set(${out} ${seen} PARENT_SCOPE)
endfunction()

function(stereod_check_links_exclude target pattern why)
  _stereod_link_closure(${target} closure)
  foreach(link IN LISTS closure)
    if(link MATCHES "${pattern}")
      message(FATAL_ERROR "${target} links ${link} (through: ${closure}): ${why}")
    endif()
  endforeach()
endfunction()
