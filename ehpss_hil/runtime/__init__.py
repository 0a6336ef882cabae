"""The real-time runtime shared by the controller daemon and the plant emulator: deadline grid,
loop statistics, RT options, signal handling, watchdog, lifecycle (docs/design.md §8)."""
