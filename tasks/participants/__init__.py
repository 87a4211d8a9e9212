"""Virtual participants: simulated people whose IMU frames go through the real chain.

Map (data flows down):

- ``params``: a participant file (``<name>.toml`` here) as ``ParticipantParams``: its schema and validation.
- ``motion``: the body's pieces: minimum-jerk moves, coloured noise (sway, tremor), the ground truth.
- ``participant``: ``VirtualParticipant`` performing intents (reaction and move times, spasms) and the
  calibration protocol (``calibration_session``, ``protocol_session``), recorded as ``bomi record``
  would -> node angles.
- ``imu_synth``: node angles -> raw accelerometer/gyroscope/magnetometer counts -> deliveries of
  base-station samples (link model, sensor noise).
- ``receiver``: the host end of the link in a simulated episode: a chunk of deliveries through the
  parser and the streaming chain at once, each decision handed out at its frame's arrival.
- ``wire``: a participant as base-station byte blocks (``bomi emulate --participant``).
- ``holds``: what a recording's held postures show (levels, sway, tremor, spread, drift, least lean).
- ``twin``: the fitter (``bomi twin``) of a participant to a person's calibration recording(s), with
  per-parameter provenance and the recording's protocol (``bomi synth`` performs it); the timing from
  the moves ``bomi.onsets`` finds in continuous recordings; ``P1.toml`` is its fit of P1's five days
  (but for ``[feel] least_lean``, kept at the assumed 0.5 its task figures were made with).
- ``population``: synthetic people drawn for the classifier's policy checks.
- ``P1.toml``, ``P4.toml``, ``P5.toml``: the shipped participants (numbers, no data).
"""
