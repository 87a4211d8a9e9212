"""Experiments over the task and the signal chain: the library the `bomi` command line (tasks/cli/,
which only parses arguments and prints) and the benchmarks (benchmarks/) both call.

- ``jobs``: ``EpisodeJob`` (everything an episode depends on), ``run_job`` (one episode, the BoMI
  calibrated first), ``episode_record``, ``benchmark_jobs`` and ``run_many`` (many on an engine).
- ``summary``: episode records pooled into rows (``aggregate``: successes and times with 95 %
  intervals, decision metrics), ``comparison`` with the paper, the benchmark's JSON payload.
- ``tables``: those rows as markdown (files) and as aligned text (the terminal).
- ``demo``: `bomi demo`'s two episodes on one seed: the film, the timeline, the records.
- ``figures``: completion times, a metric against a swept setting, confusion matrices.
- ``training``: a person's classifier trained from their recordings, its quality reported.
- ``twins``: a twin checked against the person it was fitted to; the paper's protocol.
- ``design``: candidate layouts of a person written as profiles and run by their twin.
- ``streams``: recording from a base-station stream (nodes, the settle wait, timing, segments).
- ``trials``: `bomi trial`'s bookkeeping: the directory's lock, the trials to run, each finished
  trial written as it finishes, scored, and a virtual participant's prediction of them.
- ``stop``: termination signals kept as a request that every tick checks (a swallowed raise still
  ends the session).
- ``limits``: the largest seeds, seed counts and durations any run accepts.
- ``engine`` and ``sweep`` (process pool or Ray; grids of settings x seeds, resumable).
- ``faults``: the fault corpora run through the command line (damaged files, session faults, the live
  loop's safety), for `python benchmarks/faults.py`.
"""
