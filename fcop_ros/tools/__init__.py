"""The command-line tools: bag replay and playback, bag writing, the demo, the NOCS data-set
evaluation, and what they share (bag I/O, the help format)."""
