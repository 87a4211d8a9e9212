"""Stacking task benchmark: success, completion time, real-time accuracy beside the paper's figures,
and the speed of a BoMI episode on one core.

    python benchmarks/task_benchmark.py [--participants P1] [--seeds 20] [--first-seed 0] [--jobs 2]
                                        [--name task_benchmark] [--records FILE ...] [--figure-only]

Writes benchmarks/results/<name>.md, .json, .png (completion time of every episode) and
_accuracy.png (accuracy against the excused allowance); ``--records`` builds them from saved
episode records instead of running episodes, ``--figure-only`` redraws the figures from the saved
JSON.  The episodes run in parallel processes
(``bomi benchmark``'s code); the speed figures come from one more BoMI episode run alone, and
from the chain's per-sample cost measured on the frames of that episode's participant.
"""
from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

from bomi import paper
from bomi.chain import OnlineChain
from bomi.classifier import PostProcessing
from bomi.frames import FrameParser, imu_index
from tasks.experiments.engine import ProcessPool
from tasks.experiments.figures import accuracy_allowance_figure, completion_time_figure
from tasks.experiments.jobs import DEFAULT_VOTE, JOYSTICK_ANYONE, EpisodeJob, benchmark_jobs, run_job, run_many
from tasks.experiments.summary import aggregate, comparison
from tasks.experiments.tables import markdown_tables
from tasks.stacking.channels import calibrated_channel
from tasks.stacking.summary import summarize
from tasks.participants.participant import VirtualParticipant, load_participant
from tasks.operators.params import DEFAULT_OPERATOR_FILE

RESULTS = Path(__file__).resolve().parent / "results"
TIME_LIMIT = 600.0


def chain_cost_ms(participant: str, seed: int, seconds: float = 60.0) -> float:
    """Wall time per node-1 sample of parser + fusion + features + LDA + vote, on one core."""
    channel = calibrated_channel(participant, seed, PostProcessing(vote_length=DEFAULT_VOTE))
    body = VirtualParticipant(load_participant(participant), channel.profile, seed + 1)
    for k, label in enumerate((1, 3, 0, 2, 4, 0)):
        body.set_intent(label, 1.0, 5.0 * k)
    data = body.advance(seconds)
    chain = OnlineChain(channel.chain.model, channel.profile)
    started = time.perf_counter()
    frames = FrameParser().feed(data)
    chain.push_frames(frames)
    elapsed = time.perf_counter() - started
    return 1000.0 * elapsed / sum(imu_index(frame.node_id) == 1 for frame in frames)


def _row_key(r: dict) -> tuple[str, str, str]:
    return (JOYSTICK_ANYONE if r["operator"] == "joystick" else r["participant"], r["operator"], r["layout"])


def figure(records: list[dict], path: Path) -> None:
    """Completion time of every episode per row, with the paper's mean times; beside it
    (``<path>_accuracy.png``) each BoMI row's accuracy against the allowance excused after every
    intent change."""
    groups = sorted({_row_key(r) for r in records})
    completion_time_figure([("\n".join(key), [r for r in records if _row_key(r) == key]) for key in groups], path,
                           "Stacking task: every episode (line: mean of successes; x: failed, where it stopped)",
                           {"paper BoMI": paper.TASK["bomi_time_s"], "paper joystick": paper.TASK["joystick_time_s"]})
    accuracy_allowance_figure(aggregate(records), path.with_name(path.stem + "_accuracy.png"),
                              {f"paper {100 * paper.TASK['realtime_accuracy']:.1f} % (outputs not irrelevant)":
                               paper.TASK["realtime_accuracy"]})


def read_records(paths: list[Path]) -> list[dict]:
    """Episode records saved by ``bomi benchmark --json`` (its ``episodes``) or ``bomi sweep`` (episodes.jsonl)."""
    records = []
    for path in paths:
        text = Path(path).read_text(encoding="utf-8")
        records += ([json.loads(line) for line in text.splitlines() if line.strip()] if str(path).endswith(".jsonl")
                    else json.loads(text)["episodes"])
    return records


def write_results(records: list[dict], name: str, note: str, speed: dict | None) -> str:
    """benchmarks/results/<name>.md, .json, .png and _accuracy.png from the episode records."""
    rows = aggregate(records)
    seeds = sorted({r["seed"] for r in records})
    lines = [f"# Stacking task benchmark (seeds {seeds[0]}-{seeds[-1]}, {len(seeds)} per row)", "",
             f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}; {note}; "
             f"BoMI majority vote {DEFAULT_VOTE}.", "",
             markdown_tables(rows), "",
             "Brackets: 95 % intervals (successes: Wilson score; completion time: Student-t interval of the mean "
             f"of the successes). Paper (Fall et al.): BoMI {paper.TASK['bomi_time_s']:.0f} s, joystick "
             f"{paper.TASK['joystick_time_s']:.0f} s, real-time accuracy {100 * paper.TASK['realtime_accuracy']:.1f} % "
             f"(outputs not misclassified due to irrelevancy: compare with 'relevant outputs'), longest error run "
             f"{paper.TASK['longest_error_run_ms']:.0f} ms.", ""]
    failures = [f"- {r['participant']} {r['operator']} seed {r['seed']}: {r['failure']}" for r in records if not r["success"]]
    lines += ["Failed episodes:" if failures else "No episode failed.", *failures, ""]
    if speed is not None:
        lines += ["| speed (one BoMI episode alone, one core) | value |", "|---|---|",
                  f"| simulated time (s) | {speed['bomi_episode_sim_s']:.1f} |",
                  f"| wall time (s) | {speed['bomi_episode_wall_s']:.1f} |",
                  f"| x real time, wall clock (bar: >= 12) | {speed['bomi_realtime_factor_one_core']:.1f} |",
                  f"| x real time, process CPU time | {speed['bomi_realtime_factor_cpu']:.1f} |",
                  f"| chain cost per sample (ms, budget 1) | {speed['chain_ms_per_sample']:.3f} |", ""]
    text = "\n".join(lines)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.md").write_text(text, encoding="utf-8")
    (RESULTS / f"{name}.json").write_text(json.dumps(
        {"paper": paper.TASK, "seeds": seeds, "rows": rows, "comparison": comparison(rows), "speed": speed,
         "episodes": records}, indent=2) + "\n", encoding="utf-8")
    figure(records, RESULTS / f"{name}.png")
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--participants", default="P1")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="first seed (0-999: development seeds; 10000-19999: held out, a fresh range "
                             "run once frozen; 1000-4999 spent)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--name", default="task_benchmark", help="results file name in benchmarks/results/")
    parser.add_argument("--records", nargs="+", type=Path,
                        help="no episodes run: the results from saved records (bomi benchmark --json, sweep episodes.jsonl)")
    parser.add_argument("--figure-only", action="store_true", help="redraw the figures from the saved JSON")
    args = parser.parse_args()
    if args.figure_only:
        saved = json.loads((RESULTS / f"{args.name}.json").read_text(encoding="utf-8"))
        figure(saved["episodes"], RESULTS / f"{args.name}.png")
        return
    if args.records:
        print(write_results(read_records(args.records), args.name,
                            f"episodes from {', '.join(p.name for p in args.records)}", None))
        return
    participants = [p.strip() for p in args.participants.split(",")]
    records = run_many(benchmark_jobs(participants, ["joystick", "bomi"], args.seeds, TIME_LIMIT,
                                      str(DEFAULT_OPERATOR_FILE), first_seed=args.first_seed), ProcessPool(args.jobs))
    alone = summarize(run_job(EpisodeJob("bomi", participants[0], 0)))
    speed = {"bomi_episode_sim_s": alone["sim_time"], "bomi_episode_wall_s": alone["wall_time"],
             "bomi_realtime_factor_one_core": alone["realtime_factor"],
             "bomi_realtime_factor_cpu": alone["realtime_factor_cpu"],
             "chain_ms_per_sample": chain_cost_ms(participants[0], 0)}
    print(write_results(records, args.name, f"episodes in {args.jobs} parallel processes", speed))


if __name__ == "__main__":
    main()
