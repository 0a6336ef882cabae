"""Bounds on input files: the one home of every cap the loaders apply.

Configs, scenarios and reference trajectories come from people and from other programs; each is
read once, before any bus is opened, within these bounds. A file beyond a bound is a
:class:`~ehpss_hil.errors.ConfigError` (exit 2, one line), never a hang, a traceback or gigabytes.
The shipped files are far inside them (the largest YAML is about 2 kB).
"""

from __future__ import annotations

#: largest YAML config or scenario file read (bytes); pure-Python YAML parses ~0.5 MB/s
MAX_YAML_BYTES = 256 * 1024
#: deepest nesting of mappings/sequences in a YAML file (the shipped files use 3)
MAX_YAML_DEPTH = 32
#: most YAML nodes (scalars, mappings, sequences) in one file
MAX_YAML_NODES = 100_000
#: wall-time limit for reading and parsing one input file (s)
MAX_PARSE_S = 5.0

#: largest reference trajectory CSV (``reference: {kind: file}``) read (bytes)
MAX_REFERENCE_BYTES = 16 * 2**20
#: most rows (t_s, x_m) in a reference trajectory
MAX_REFERENCE_ROWS = 1_000_000

#: most samples in a scenario (duration_s / sample_time_s): the lockstep simulator keeps
#: about 1.3 kB per sample (arrays of every signal), so this bounds one run to ≈ 1.6 GB
MAX_SCENARIO_SAMPLES = 1_200_000
#: a non-zero reference amplitude (m) or ramp rate (m/s) is at least this: the adaptive layer
#: normalizes by the spool amplitude it implies (10 position LSBs of the DBC, 0.1 µm each)
MIN_REFERENCE_SCALE = 1e-6

#: a value quoted in an error message is cut to this many characters
MAX_SHOWN_CHARS = 60
#: an error message (file, key path and reason) is cut to this many characters
MAX_MESSAGE_CHARS = 400

#: largest |x_d| a reference may ask for (m): the DBC's position range (±0.5 m)
MAX_REFERENCE_M = 0.5

#: loop rates of the controller and the emulator (Hz); a scenario's sample time is within
#: their inverses, so every scenario the simulator runs also runs on the bench
MIN_RATE_HZ = 10.0
MAX_RATE_HZ = 10000.0

#: largest DBC file read (bytes): cantools keeps ~70 bytes of objects per byte of DBC (a 20 MB
#: file took 1.4 GB and 44 s); vendor DBCs of a whole machine are a few hundred kB
MAX_DBC_BYTES = 2 * 2**20

#: most runs in one campaign file (``samples``); each run simulates every mode of the campaign
MAX_CAMPAIGN_RUNS = 1_000_000
#: most faults injected at once in one campaign run (one per fault kind at most)
MAX_FAULTS_PER_RUN = 7

#: most decoded signal values a report holds (float64 cells, 8 bytes each, over all frame
#: names; a multiplexed frame counts every signal of its name): a bench log at 1 kHz decodes
#: about 49 per controller cycle (its sensor, truth, command, index and status frames)
MAX_LOG_VALUES = 16_000_000
#: most controller samples a report lays out in memory at once (about 0.5 kB each with the
#: metrics and the reference model): 6.7 min at 1 kHz. With :data:`MAX_LOG_VALUES` a log read
#: whole stays below ≈ 450 MB; a longer log is read in chunks (``report.logstream``), each of
#: at most this many samples — a ``CycleCount`` that jumps by more inside one chunk (logs of
#: several runs joined) is refused with one line instead of becoming millions of empty samples.
MAX_LOG_SAMPLES = 400_000
#: most controller samples ``report`` reads from one log in chunks: 10 h at 1 kHz. Memory does
#: not grow with them; the scratch file of the metrics does (≈ 50 bytes a sample: 1.8 GB here,
#: in the temporary directory) and so does the time (≈ 40 µs a sample); beyond, one line
MAX_STREAMED_SAMPLES = 36_000_000
#: largest sidecar ``<log>.json`` (or ``run.json``) read (bytes); ours are a few kB, with a
#: scenario's reference table inline at most that table (:data:`MAX_REFERENCE_BYTES`)
MAX_SIDECAR_BYTES = 32 * 2**20
#: deepest nesting of objects/arrays in a sidecar (ours use 4)
MAX_SIDECAR_DEPTH = 32
#: a log's sample time (s) read from its metadata or timing is within these: the inverses of
#: the loop rates (:data:`MAX_RATE_HZ`, :data:`MIN_RATE_HZ`)
MIN_LOG_SAMPLE_TIME_S = 1.0 / MAX_RATE_HZ
MAX_LOG_SAMPLE_TIME_S = 1.0 / MIN_RATE_HZ
