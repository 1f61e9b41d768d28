"""evaluate_dataset without Ray: the input kinds, results.jsonl and resuming, the merged report, the CLI's errors.

The official layout is read from the reference data where it is there (``../shared``), and written here
from the views of a shipped demo bag otherwise: the same views as a bag and as official files must give
the same estimate. The model is the embedded demo model with a reduced solver (wiring, not accuracy).
"""
import json
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from idpose_core.evaluation.object_frame import object_frame_c2w
from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.evaluation.run import run_estimate
from idpose_core.evaluation.scoring import random_baseline, score_poses
from idpose_ros import evaluate_dataset
from idpose_ros.dataset.inputs import InputError, open_inputs, read_png_view
from idpose_ros.dataset.ray_runner import JobResult
from idpose_ros.dataset.report import merge, write_dataset_report
from idpose_ros.dataset.results import ResultsLog, SettingsMismatch, result_line, task_key
from idpose_ros.evaluation.bag_views import load_views
from idpose_ros.evaluation.estimators import EstimatorOptions, make_estimator
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views

ROOT = Path(__file__).resolve().parents[1]
DUCK = ROOT / "data" / "demo_bags" / "duck"
REFERENCE = ROOT.parent / "shared" / "reference" / "idpose-official"
SOLVER = ("azimuth_candidates=2", "adjust_steps=0", "probe_batch=1", "refine_steps_per_view=2", "runner_up_steps=0")
OPTIONS = EstimatorOptions(preset="fast", solver_params=SOLVER, image_size=64, device="cpu")
REDUCED = ["--preset", "fast", "--image-size", "64", "--device", "cpu",
           *(arg for item in SOLVER for arg in ("--solver-param", item))]
BLANK = 99  # an official view without an object: its estimate fails in preprocessing


def write_official_layout(bag: Path, root: Path, samples: list[tuple[int, ...]], blank_sample: bool = False) -> Path:
    """The bag's views in the official layout (``<root>/synthetic/duck``), its samples in ``<root>/duck.json``;
    with ``blank_sample``, one more sample whose target is a transparent image (view ``BLANK``)."""
    gt = GroundTruthOptions()
    views = read_views(bag, gt)
    ids = sorted({v for sample in samples for v in sample})
    folder = root / "synthetic" / "duck"
    (folder / "images").mkdir(parents=True)
    (folder / "poses").mkdir()
    for view, decoded in load_views(bag, gt.image_topic, set(ids), views)[0].items():
        cv2.imwrite(str(folder / "images" / f"{view:03d}.png"), cv2.cvtColor(np.dstack([decoded.rgb, decoded.alpha]),
                                                                              cv2.COLOR_RGBA2BGRA))
        np.save(folder / "poses" / f"{view:03d}.npy", object_frame_c2w(views.world_from_camera[view], gt.object_center,
                                                                      gt.up))
    specs = [{"name": "duck", "anchor_vid": s[0], "target_vids": list(s[1:]), "init_poses": {}} for s in samples]
    if blank_sample:
        cv2.imwrite(str(folder / "images" / f"{BLANK:03d}.png"), np.zeros((64, 64, 4), np.uint8))
        np.save(folder / "poses" / f"{BLANK:03d}.npy", np.load(folder / "poses" / f"{ids[1]:03d}.npy"))
        specs.append({"name": "duck", "anchor_vid": samples[0][0], "target_vids": [BLANK], "init_poses": {}})
    path = root / "duck.json"
    path.write_text(json.dumps({"data_root": "synthetic/", "samples": specs}))
    return path


@pytest.fixture(scope="module")
def estimator():
    estimator = make_estimator(OPTIONS)
    yield estimator
    estimator.close()


@pytest.fixture(scope="module")
def duck_both_ways(tmp_path_factory):
    """(bag input, official input) of the same views: the official samples are the bag's first two picks."""
    bag = open_inputs([str(DUCK)], GroundTruthOptions())[0]
    picks = [task.pick for task in bag.plan(EvaluationProtocol(samples=2, seed=0, view_counts=(2, 4)))]
    samples = list(dict.fromkeys(pick[:4] for pick in picks))
    official = open_inputs([str(write_official_layout(DUCK, tmp_path_factory.mktemp("official"), samples))],
                           GroundTruthOptions())
    return bag, official[0]


def test_official_samples_fix_the_views_and_their_ground_truth_is_the_official_one():
    """The reference omni3d samples: anchor first as named, rgba8 images, the official gt_rel_sph per pair."""
    if not (REFERENCE / "omni3d.json").is_file():
        pytest.skip(f"official reference data not found under {REFERENCE}")
    inputs = open_inputs([str(REFERENCE / "omni3d.json")], GroundTruthOptions())
    assert [(item.kind, item.dataset, Path(item.name).name) for item in inputs] == [
        ("official", "omni3d", "house_001"), ("official", "omni3d", "ornaments_001"),
        ("official", "omni3d", "dinosaur_002")]
    for item in inputs:
        tasks = item.plan(EvaluationProtocol(view_counts=(2, 4, 6, 8)))
        assert [task.n for task in tasks] == [2, 4]  # four views per sample: n = 6 and 8 do not fit
        task = tasks[-1]
        output = next(REFERENCE.glob(f"outputs/omni3d/{Path(item.name).name}_*/pose.json"))
        official = json.loads(output.read_text())
        assert task.pick[0] == int(official["anchor_vid"])
        for target, pair in zip(task.pick[1:], score_poses(np.stack([np.eye(4)] * 4), task.true_c2w)):
            expected = np.array(official["obs"][f"{target:03d}"]["gt_rel_sph"])
            expected[1] %= 2 * np.pi
            np.testing.assert_allclose(pair["true_rel_sph"], expected, atol=1e-6)
        view = item.views({task.pick[0]})[0][task.pick[0]]
        png = cv2.imread(str(REFERENCE / "data" / "omni3d" / Path(item.name).name / "images"
                             / f"{task.pick[0]:03d}.png"), cv2.IMREAD_UNCHANGED)
        assert view.rgb.shape[:2] == png.shape[:2]
        np.testing.assert_array_equal(view.alpha, png[..., 3])
        np.testing.assert_array_equal(view.rgb, png[..., 2::-1])


def test_png_views_take_grey_rgb_and_rgba(tmp_path):
    pixels = np.random.default_rng(0).integers(0, 256, (5, 7, 4), dtype=np.uint8)
    for channels in (1, 3, 4):
        path = tmp_path / f"{channels}.png"
        cv2.imwrite(str(path), pixels[..., 0] if channels == 1 else pixels[..., :channels])
        view = read_png_view(path)
        assert view.rgb.shape == (5, 7, 3) and (view.alpha is not None) == (channels == 4)
        expected = np.repeat(pixels[..., :1], 3, axis=2) if channels == 1 else pixels[..., 2::-1]
        np.testing.assert_array_equal(view.rgb, expected)
        if channels == 4:
            np.testing.assert_array_equal(view.alpha, pixels[..., 3])
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match="not an 8-bit image"):
        read_png_view(tmp_path / "broken.png")


@pytest.mark.slow
def test_the_same_views_as_a_bag_and_as_official_files_give_the_same_estimate(duck_both_ways, estimator):
    bag, official = duck_both_ways
    bag_tasks = bag.plan(EvaluationProtocol(samples=2, seed=0, view_counts=(2, 4)))
    official_tasks = official.plan(EvaluationProtocol(samples=2, seed=0, view_counts=(2, 4)))
    assert [(t.sample, t.index, t.pick[:t.n]) for t in official_tasks] == [
        (t.sample, t.index, t.pick[:t.n]) for t in bag_tasks]
    for bag_task, official_task in zip(bag_tasks[:2], official_tasks[:2]):
        np.testing.assert_allclose(official_task.true_c2w, bag_task.true_c2w[:4], atol=1e-12)
        outcomes = [run_estimate(estimator, task, [item.views(set(task.pick))[0][v] for v in task.views])
                    for item, task in ((bag, bag_task), (official, official_task))]
        pairs = [[{k: v for k, v in pair.items() if k != "seconds"} for pair in outcome.records]
                 for outcome in outcomes]
        assert pairs[0] == pairs[1]
        assert outcomes[0].random_records == outcomes[1].random_records


def test_a_samples_file_that_does_not_fit_says_why(tmp_path):
    (tmp_path / "bad.json").write_text('{"samples": []}')
    with pytest.raises(InputError, match="not an ID-Pose samples file"):
        open_inputs([str(tmp_path / "bad.json")], GroundTruthOptions())
    (tmp_path / "missing.json").write_text(json.dumps({"data_root": "data/", "samples": [
        {"name": "cup", "anchor_vid": 1, "target_vids": [2]}]}))
    with pytest.raises(InputError, match=r"no images/<vid>.png and poses/<vid>.npy for views \[1, 2\]"):
        open_inputs([str(tmp_path / "missing.json")], GroundTruthOptions())
    with pytest.raises(InputError, match="matches no file"):
        open_inputs([str(tmp_path / "*.mcap")], GroundTruthOptions())


def finished(item, task, estimator, attempts: int = 1) -> JobResult:
    """The JobResult a worker would send for this task."""
    outcome = run_estimate(estimator, task, [item.views(set(task.pick))[0][v] for v in task.views])
    return JobResult(task_key(item.name, task), task, attempts, outcome, "host:1")


@pytest.mark.slow
def test_results_resume_and_the_report_merges_in_plan_order(tmp_path, duck_both_ways, estimator):
    """Lines written out of order, one failed, a torn last line: the rerun's view and the merged report."""
    bag, official = duck_both_ways
    protocol = EvaluationProtocol(samples=1, seed=0, view_counts=(2, 4))
    planned = [(bag, bag.plan(protocol)), (official, official.plan(protocol))]
    settings = {"model": "demo", "seed": 0}
    with ResultsLog(tmp_path, settings) as log:
        (bag_2, bag_4), official_4 = planned[0][1], planned[1][1][1]  # the official samples are fixed: 2 of them
        log.append(result_line(official, finished(official, official_4, estimator), 0))
        log.append(result_line(bag, JobResult(task_key(bag.name, bag_2), bag_2, 2, error="ValueError: boom"), 0))
        log.append(result_line(bag, finished(bag, bag_4, estimator, attempts=2), 0))
    with (tmp_path / "results.jsonl").open("a") as file:
        file.write('{"input": "torn by a cra')
    with ResultsLog(tmp_path, settings) as log:
        assert (tmp_path / "results.jsonl").read_text().endswith("}\n")  # the torn line is gone
        assert [log.done(task_key(item.name, task)) for item, tasks in planned for task in tasks] == [
            False, True, False, True, False, False]  # the failed estimate runs again
        line = log.lines[task_key(bag.name, bag_4)]
        assert line["status"] == "ok" and line["attempts"] == 2 and line["worker"] == "host:1"
        assert line["seeds"] == {"protocol": 0, "solver": 0, "random_baseline": [0, 1, 4]}
        assert np.array(line["true_c2w"]).shape == np.array(line["predicted_c2w"]).shape == (4, 4, 4)
        about = {"mode": "offline", "model": {"model_path": ""}, "node_parameters": {"variant": "full",
                                                                                       "solver_preset": "fast"},
                 "protocol": {"samples": 1, "seed": 0, "view_counts": [2, 4]}}
        evaluation = merge(planned, log.lines, about)
    with pytest.raises(SettingsMismatch, match="other seed"):
        ResultsLog(tmp_path, {**settings, "seed": 1})
    ResultsLog(tmp_path / "no_results", settings).close()  # e.g. stopped on a wrong model path: nothing is bound
    ResultsLog(tmp_path / "no_results", {**settings, "seed": 1}).close()
    assert json.loads((tmp_path / "no_results" / "run.json").read_text())["seed"] == 1

    assert [(r["input"], r["n"], r["view"]) for r in evaluation.records] == [
        (bag.name, 4, v) for v in bag_4.pick[1:4]] + [(official.name, 4, v) for v in official_4.pick[1:4]]
    assert evaluation.failures == [{"input": bag.name, "sample": 0, "n": 2, "views": list(bag_2.pick[:2]),
                                    "attempts": 2, "error": "ValueError: boom"}]
    assert evaluation.missing == 3  # estimates that never ran
    assert evaluation.random_records[:600] == [{"input": bag.name, "dataset": "demo_bags", **guess}
                                               for guess in random_baseline(bag_4.true_c2w[:4], (0, 1, 4))]
    markdown = write_dataset_report(tmp_path, evaluation)
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["estimates"] == {"planned": 6, "succeeded": 2, "failed": 1, "missing": 3}
    assert list(report["datasets"]) == ["demo_bags", "synthetic"]
    assert report["datasets"]["demo_bags"]["aggregates"]["4"]["pairs"] == 3
    assert report["datasets"]["demo_bags"]["random_baseline"]["aggregates"]["4"]["pairs"] == 600
    assert report["all"]["aggregates"]["all"]["pairs"] == 6
    assert "## demo_bags\n\n1 input, 1 estimates, 1 failed." in markdown and "## all data sets" in markdown
    assert "| ID-Pose (full) | 4 |" in markdown and "| random poses | 4 |" in markdown
    assert "| demo_bags/duck | 3 |" in markdown and "| synthetic/duck | 3 |" in markdown
    assert "(2 attempts): ValueError: boom" in markdown and "3 not run yet" in markdown
    assert cv2.imread(str(tmp_path / "errors.png")) is not None


def test_the_cli_refuses_replay_and_bad_inputs(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        evaluate_dataset.main([str(DUCK), "--mode", "replay", "--out", str(tmp_path / "o")])
    assert exit_info.value.code == 2 and "--mode replay needs a ROS node per worker" in capsys.readouterr().err
    assert evaluate_dataset.main([str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 2
    assert "evaluate_dataset: error:" in capsys.readouterr().err and not (tmp_path / "o").exists()
    assert evaluate_dataset.main([str(DUCK), "--n", "8", "--out", str(tmp_path / "o"),
                                  "--solver-param", "keep_top=0"]) == 2
    assert "keep_top" in capsys.readouterr().err


@pytest.mark.slow
def test_ros2_run_finds_evaluate_dataset(workspace):
    """As `ros2 run idpose_ros evaluate_dataset` runs it: the installed script, on the installed demo bag."""
    prefix = workspace / "install" / "idpose_ros"
    bag = prefix / "share" / "idpose_ros" / "data" / "demo_bags" / "duck"
    script = (f". {workspace / 'install' / 'setup.sh'} && "
              f"{prefix / 'lib' / 'idpose_ros' / 'evaluate_dataset'} {bag} --mode replay")
    result = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and "--mode replay needs a ROS node per worker" in result.stderr, result.stderr
