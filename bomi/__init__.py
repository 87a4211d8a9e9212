"""The BoMI signal chain: frames -> fusion -> windows/features -> classifier -> joystick commands.

Imports nothing from ``sim/`` or ``tasks/``. Map (data flows down; batch and streaming share each stage):

- sources of samples: ``frames`` (the base station's 32-byte frames), ``serial_source`` (a live
  port), ``emulator`` (a base station in software), ``recording`` (.mat/.csv files as they come),
  ``logger_layout`` (the original logger's file layout), ``dataset`` (where P1's recordings live).
- ``gate``: whether a live node's stream can be trusted to move the arm (warm-up, plausibility, breaks).
- ``fusion``: each node's orientation; ``neutral``: how a person's rests scatter.
- ``features``: windows and FV1-FV3; ``classifier``: the LDA, post-processing, proportional output.
- ``chain``: the stages composed: training windows and copies, training, settings selection,
  evaluation, the streaming chain (``OnlineChain``).
- a person's recording: ``passes`` (the protocol's passes found), ``onsets`` (each move's onset and
  offset from the signals), ``protocol`` (the calibration protocol), ``derived`` (a profile derived
  from a recording), ``profiles`` (the shipped profiles and their format).
- files: ``model_io`` (model files, never pickles), ``config_files`` (the one TOML loader),
  ``files`` (atomic outputs), ``errors`` (one-line errors).
- the paper: ``paper`` (its figures), ``reproduce`` (its accuracy-over-days table); ``compiled``
  (numba kernels, or plain Python without numba).
"""
