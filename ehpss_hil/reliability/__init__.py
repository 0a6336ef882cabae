"""The reliability suite (docs/design.md §11, issue 8): what ``ehpss-hil bench faults`` measures.

One module per fault class, each returning plain result objects the bench prints and the tests
assert on: ``fuzz`` (frames with a known verdict and random ones through the codec, the
controller loop and the emulator), ``loss`` (per-direction frame loss, lockstep simulator and
processes), ``duplicates`` (duplicated/reordered/burst sensor frames against a controller
process), ``kills`` (kill -9 / SIGTERM of either process), ``badinput`` (every config and
scenario key made wrong). ``procs`` and ``logcheck`` are the shared process and log tools.
"""
