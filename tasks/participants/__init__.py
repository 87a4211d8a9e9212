"""Virtual participants: simulated people whose IMU frames go through the real chain.

Map (data flows down):

- ``participant``: the participant model (``ParticipantParams`` read from ``<name>.toml`` here,
  ``VirtualParticipant`` performing classes, calibration sessions) -> node angles.
- ``imu_synth``: node angles -> raw accelerometer/gyroscope/magnetometer counts -> deliveries of
  base-station samples (link model, sensor noise).
- ``receiver``: the host end of the link in a simulated episode: a chunk of deliveries through the
  parser and the streaming chain at once, each decision handed out at its frame's arrival.
- ``wire``: a participant as base-station byte blocks (``bomi emulate --participant``).
- ``twin``: the fitter (``bomi twin``) of a participant to a person's calibration recording(s), with
  per-parameter provenance and the recording's protocol (``bomi synth`` performs it); ``P1.toml`` is
  its fit of P1's five days.
- ``P1.toml``, ``P4.toml``, ``P5.toml``: the shipped participants (numbers, no data).
"""
