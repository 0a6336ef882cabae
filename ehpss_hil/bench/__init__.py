"""Benchmarks, one module per ``ehpss-hil bench KIND`` (NAME, HELP, add_arguments, run)."""
