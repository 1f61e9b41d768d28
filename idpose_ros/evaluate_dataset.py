"""`evaluate_dataset INPUT...`: the paper's pose metrics over many inputs, one Ray task per estimate.

Inputs, in any mix: rosbag2 bags (folders, .mcap, .db3, globs; views and ground truth as ``evaluate_bag``
reads them, seeded picks of 8 views), the node's flight recordings (a recorder's .mcap, or a folder of them
such as a ``record_dir``: each published result estimated again and scored as published, as ``evaluate_bag``
does, row "as estimated live") and official ID-Pose samples files (a .json naming the anchor and target
views of ``<data_root>/<object>/images/*.png`` + ``poses/*.npy``; its samples fix the views).
Every estimate (input x sample x n) is one call on a Ray actor that holds the model (one per worker), on
a local Ray instance or on a cluster (``--address``). Results stream to ``--out``/results.jsonl as
estimates finish; a rerun with the same ``--out`` skips the finished ones. A failed estimate is retried
once, then recorded with its error. ``--baselines`` runs the classical methods on the same views, as
``evaluate_bag`` does. Writes report.json, report.md and errors.png into ``--out``.

A thin front end: the inputs, the Ray runner, the results log and the report are ``idpose_ros.dataset``.
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from tqdm import tqdm

from idpose_core.evaluation.protocol import EstimateTask, EvaluationProtocol
from idpose_ros.cli_options import (
    add_baseline_arguments,
    add_estimator_arguments,
    add_ground_truth_arguments,
    add_protocol_arguments,
    estimator_options,
    ground_truth_options,
    protocol_options,
)
from idpose_ros.dataset.inputs import DatasetInput, InputError, open_inputs
from idpose_ros.dataset.ray_runner import EstimatorPool, Job, JobResult, RunnerError, WorkerResources, ray_session
from idpose_ros.dataset.report import merge, write_dataset_report
from idpose_ros.dataset.results import ResultsLog, result_line, task_key
from idpose_ros.evaluation.bag_io import BagError
from idpose_ros.evaluation.estimators import EstimatorOptions
from idpose_ros.evaluation.ground_truth import GroundTruthOptions

INTERRUPTED = 130  # the shell's exit code for a process stopped by Ctrl-C


def parse_args(argv: list[str] | None) -> tuple[argparse.Namespace, EvaluationProtocol]:
    parser = argparse.ArgumentParser(prog="evaluate_dataset", description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    parser.add_argument("inputs", nargs="+", help="rosbag2 bags (folders, .mcap, .db3; globs), flight recordings "
                                                  "(.mcap, or folders of them) and official ID-Pose samples files "
                                                  "(.json)")
    parser.add_argument("--out", type=Path, default=Path("dataset_evaluation"),
                        help="results and report folder; rerun into it to resume (default ./dataset_evaluation)")
    add_protocol_arguments(parser, samples_help="random picks of 8 views per bag (official samples are fixed)")
    add_baseline_arguments(parser)
    group = parser.add_argument_group("Ray")
    group.add_argument("--address", default=None,
                       help="a running Ray cluster (e.g. auto, or HEAD_IP:6379); default: a local instance")
    group.add_argument("--workers", type=int, default=None,
                       help="workers, each holding one model (default: as many as the cluster's CPUs/GPUs hold)")
    group.add_argument("--num-cpus-per-worker", type=int, default=1, help="CPUs (= torch threads) per worker")
    group.add_argument("--num-gpus-per-worker", type=float, default=0.0, help="GPUs per worker (1: one per GPU)")
    add_ground_truth_arguments(parser)
    add_estimator_arguments(parser)
    args = parser.parse_args(argv)
    if args.mode != "offline":
        parser.error("--mode replay needs a ROS node per worker: evaluate_dataset runs --mode offline "
                     "(evaluate_bag --mode replay evaluates one bag through the node)")
    if args.workers is not None and args.workers < 1:
        parser.error(f"--workers must be at least 1, got {args.workers}")
    if args.num_cpus_per_worker < 1 or args.num_gpus_per_worker < 0:
        parser.error("--num-cpus-per-worker must be at least 1 and --num-gpus-per-worker at least 0")
    return args, protocol_options(parser, args)


def run_settings(options: EstimatorOptions, values: dict[str, Any], ground_truth: GroundTruthOptions,
                 protocol: EvaluationProtocol, baselines: Sequence[str]) -> dict[str, Any]:
    """What must not change between a run and its resumption (the model, what shapes an estimate, the seed,
    the classical baselines)."""
    return {"model": {"model_path": options.model_path, "precision": options.precision}, "node_parameters": values,
            "ground_truth": asdict(ground_truth), "seed": protocol.seed, "baselines": sorted(baselines)}


def report_header(options: EstimatorOptions, values: dict[str, Any], ground_truth: GroundTruthOptions,
                  protocol: EvaluationProtocol) -> dict[str, Any]:
    """What the report says produced its numbers."""
    return {"mode": options.mode,
            "model": {"model_path": options.model_path, "device": options.device, "precision": options.precision},
            "node_parameters": {"solver_preset": options.preset, **values},
            "protocol": {"samples": protocol.samples, "seed": protocol.seed,
                         "view_counts": sorted(set(protocol.view_counts))},
            "ground_truth": {"bags": ground_truth.description, "image_topic": ground_truth.image_topic,
                             "official": "poses/<vid>.npy (OpenGL camera-to-world, object frame)"}}


def jobs(todo: Sequence[tuple[DatasetInput, EstimateTask]], undecodable: list[JobResult]) -> Iterator[Job]:
    """The estimates to run, each with its views decoded, read one input at a time as workers become free; an
    estimate holding a view that does not decode goes to ``undecodable`` as failed instead."""
    for item, group in itertools.groupby(todo, key=lambda pair: pair[0]):
        tasks = [task for _, task in group]
        views, problems = item.views({v for task in tasks for v in task.views})
        for task in tasks:
            broken = "; ".join(f"view {v}: {problems[v]}" for v in task.views if v in problems)
            if broken:
                undecodable.append(JobResult(task_key(item.name, task), task, 0, error=broken))
                continue
            yield Job(task_key(item.name, task), task, [views[v] for v in task.views])


def run(todo: Sequence[tuple[DatasetInput, EstimateTask]], log: ResultsLog, options: EstimatorOptions,
        resources: WorkerResources, address: str | None, solver_seed: int, done_before: int,
        baselines: Sequence[str] = ()) -> None:
    """Run the estimates on Ray, appending each result to the log as it arrives; a progress bar with ETA."""
    inputs = {task_key(item.name, task): item for item, task in todo}
    failed = 0
    undecodable: list[JobResult] = []
    pool = EstimatorPool(options, resources, baselines=tuple(baselines))
    with tqdm(total=done_before + len(todo), initial=done_before, desc="estimating", unit="estimate",
              file=sys.stderr, smoothing=0.1) as bar, ray_session(address), pool:
        for result in itertools.chain(pool.run(jobs(todo, undecodable)), undecodable):
            log.append(result_line(inputs[result.key], result, solver_seed))
            failed += result.outcome is None
            if failed:
                bar.set_postfix_str(f"{failed} failed")
            bar.update()


def main(argv: list[str] | None = None) -> int:
    args, protocol = parse_args(argv)
    started = time.perf_counter()
    try:
        options, ground_truth = estimator_options(args), ground_truth_options(args)
        values = options.node_values()
        inputs = open_inputs(args.inputs, ground_truth)
        planned = [(item, item.plan(protocol)) for item in inputs]
        for item in inputs:
            for reason in item.summary().get("left_out", []):
                print(f"evaluate_dataset: {item.name}: left out {reason}", file=sys.stderr)
        log = ResultsLog(args.out, run_settings(options, values, ground_truth, protocol, args.baselines))
    except (BagError, InputError, ValueError) as err:
        print(f"evaluate_dataset: error: {err}", file=sys.stderr)
        return 2
    with log:
        todo = [(item, task) for item, tasks in planned for task in tasks if not log.done(task_key(item.name, task))]
        total = sum(len(tasks) for _, tasks in planned)
        print(f"evaluate_dataset: {len(inputs)} inputs, {total} estimates, {total - len(todo)} already in "
              f"{log.path}", file=sys.stderr, flush=True)
        resources = WorkerResources(args.workers, args.num_cpus_per_worker, args.num_gpus_per_worker)
        try:
            if todo:
                run(todo, log, options, resources, args.address, values["seed"], total - len(todo), args.baselines)
        except KeyboardInterrupt:
            finished = sum(log.done(task_key(item.name, task)) for item, tasks in planned for task in tasks)
            print(f"\nevaluate_dataset: interrupted; {finished} of {total} estimates have succeeded ({log.path}): "
                  "rerun the same command to resume", file=sys.stderr)
            return INTERRUPTED
        except (RunnerError, BagError, InputError) as err:
            print(f"evaluate_dataset: error: {err}", file=sys.stderr)
            return 2
        evaluation = merge(planned, log.lines, report_header(options, values, ground_truth, protocol))
    markdown = write_dataset_report(args.out, evaluation)
    print(markdown)
    print(f"report: {args.out / 'report.md'}, {args.out / 'report.json'} ({time.perf_counter() - started:.0f} s)")
    if evaluation.failures:
        print(f"evaluate_dataset: {len(evaluation.failures)} estimates failed (report.md lists them; a rerun tries "
              "them again)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
