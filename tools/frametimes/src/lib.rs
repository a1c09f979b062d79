//! `frametimes`: reads and compares vkterrain frame-timing logs. Filled by the frametimes issue.
