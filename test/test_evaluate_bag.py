"""evaluate_bag end to end in offline mode with a predictor that knows the truth: every metric is 100 %.

The fixture predictor is the project's RenderOracle (the ideal denoiser of the rendered scene),
told which view is which by matching each incoming preprocessed image against renders of the
bag's cameras recomputed from the seed, NOT from the bag's ground truth. So the 100 % also checks
that the ground truth read from the bag (a TF chain, in the optical convention) agrees with what
the images show. Reduced for speed: 10 views of 64 px, two picks, the solver's "fast" preset with
30 refinement steps per view and learning rates for the oracle's steeper error.
"""
import dataclasses
import json

import cv2
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from idpose_core.evaluation.protocol import EvaluationProtocol
from idpose_core.solver import SolverConfig
from idpose_core.synthetic.render_oracle import IdentifyingOracle
from idpose_core.synthetic.scenes import demo_objects, random_camera_spheres
from idpose_ros import evaluate_bag
from idpose_ros.cli_options import estimator_options, ground_truth_options
from idpose_ros.dataset.synthetic_bag import IMAGE_TOPIC, POSE_TOPIC, SyntheticBagOptions, make_bag
from idpose_ros.evaluation import bag_evaluation, estimators
from idpose_ros.evaluation.bag_io import TYPESTORE, BagWriter
from idpose_ros.evaluation.bag_report import border_views, picks_sentence, write_report
from idpose_ros.evaluation.estimators import EstimatorOptions, OfflineEstimator
from idpose_ros.evaluation.ground_truth import GroundTruthOptions, read_views

SEED, VIEWS, SIZE = 5, 10, 64
ORACLE_SOLVER = ("adjust_lr=1.0", "refine_lr=0.1", "refine_steps_per_view=30")
ORACLE_OPTIONS = EstimatorOptions(preset="fast", solver_params=ORACLE_SOLVER)


def node_values(preset: str, variant: str | None, overrides, image_size: int = 256) -> dict:
    return EstimatorOptions(preset=preset, variant=variant, solver_params=tuple(overrides),
                            image_size=image_size).node_values()


@pytest.fixture(scope="module")
def demo_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("eval") / "bag"
    make_bag(path, SyntheticBagOptions("sqlite3", "demo", None, views=VIEWS, seed=SEED, size=SIZE))
    return path


@pytest.fixture(scope="module")
def oracle():
    cameras = random_camera_spheres(np.random.default_rng(SEED), VIEWS)
    return IdentifyingOracle(demo_objects()[0], cameras, SIZE)


@pytest.fixture(scope="module")
def oracle_run(demo_bag, oracle):
    estimator = OfflineEstimator(oracle, ORACLE_OPTIONS.node_values(), {"predictor": "oracle"}, "fast")
    return bag_evaluation.evaluate_bag(demo_bag, estimator, GroundTruthOptions(IMAGE_TOPIC),
                                     EvaluationProtocol(samples=2, seed=0), show_progress=False)


def test_the_oracle_scores_100_percent_on_every_view_count(oracle_run, oracle):
    run = oracle_run
    assert len(run.picks) == 2 and run.picks[0][:2] != run.picks[1][:2]
    assert all(len(pick) == 8 and pick[0] < pick[1] and pick[2:] == sorted(pick[2:]) for pick in run.picks)
    # the oracle saw exactly the views of each estimate, in order: images and ids travel together
    assert oracle.identified[:8] == [estimate["views"] for estimate in run.estimates]
    aggregates = run.aggregates
    assert list(aggregates) == ["2", "4", "6", "8", "all"]
    assert [aggregates[k]["pairs"] for k in aggregates] == [2, 6, 10, 14, 32]
    for summary in aggregates.values():
        assert summary["rot_acc_15"] == summary["rot_acc_30"] == summary["pos_acc_0.2"] == 1.0
        assert summary["mean_rot_err_deg"] < 2.0 and summary["mean_pos_err"] < 0.05
    for record in run.records:
        np.testing.assert_allclose(record["pred_rel_sph"][:2], record["true_rel_sph"][:2], atol=np.radians(3))


def test_random_baseline_scores_uniform_guesses_of_the_same_pairs(oracle_run):
    """A uniform guess lands within 30 deg of a camera about 1 - cos(30 deg) / 2 = 6.7 % of the time."""
    run = oracle_run
    random = run.random_aggregates
    assert list(random) == ["2", "4", "6", "8", "all"]
    assert [random[k]["pairs"] for k in random] == [200 * p for p in (2, 6, 10, 14, 32)]
    assert 0.03 < random["all"]["rot_acc_30"] < 0.11 and random["all"]["rot_acc_15"] < random["all"]["rot_acc_30"]
    assert 70.0 < random["all"]["mean_rot_err_deg"] < 130.0


def test_tf_and_pose_topic_ground_truth_give_the_same_numbers(demo_bag, oracle):
    """Same picks, same estimates: the two ground-truth sources score identically (one 2-view set each)."""
    estimator = OfflineEstimator(oracle, ORACLE_OPTIONS.node_values())
    records = []
    for gt_topic in (None, POSE_TOPIC):
        run = bag_evaluation.evaluate_bag(demo_bag, estimator, GroundTruthOptions(IMAGE_TOPIC, gt_topic=gt_topic),
                                        EvaluationProtocol(samples=1, seed=3, view_counts=(2,)), show_progress=False)
        records.append(run.records)
    from_tf, from_topic = records
    assert [(r["anchor_view"], r["view"]) for r in from_tf] == [(r["anchor_view"], r["view"]) for r in from_topic]
    for a, b in zip(from_tf, from_topic):
        np.testing.assert_allclose(a["true_rel_sph"], b["true_rel_sph"], atol=1e-12)
        assert a["rot_err_deg"] == pytest.approx(b["rot_err_deg"], abs=1e-9)
        assert a["pos_err"] == pytest.approx(b["pos_err"], abs=1e-12)


def test_report_files(tmp_path, oracle_run):
    out = tmp_path / "out"
    table = write_report(out, oracle_run)
    report = json.loads((out / "report.json").read_text())
    assert report["model"] == {"predictor": "oracle"} and report["mode"] == "offline"
    assert report["aggregates"]["all"]["rot_acc_15"] == 1.0 and len(report["pairs"]) == 32
    parameters = report["node_parameters"]
    assert parameters["refine_steps_per_view"] == 30 and parameters["variant"] == "full"
    assert parameters["image_size"] == 256 and parameters["solver_preset"] == "fast"
    assert report["views"] == {"total": VIEWS, "usable": VIEWS, "skipped": []}
    assert {"sample", "n", "anchor_view", "view", "pred_rel_sph", "true_rel_sph", "rot_err_deg", "pos_err",
            "score", "ambiguous", "seconds"} <= set(report["pairs"][0])
    used = report["inputs"]["used"]
    assert (used["estimates_touching_border"], used["views_touching_border"]) == (0, 0)  # centred renders
    assert used["unreliable_views"] == sum(pair["ambiguous"] for pair in report["pairs"])
    assert all(estimate["views_touching_border"] == [] for estimate in report["estimates"])
    markdown = (out / "report.md").read_text()
    assert table in markdown and "0 had a view whose object mask touches the image border" in markdown
    assert report["protocol"]["picks_drawn"] == 2 and "2 picks of 8 views (seed 0), evaluated" in markdown
    assert "| distinct pairs |" in table
    assert "| ID-Pose (full) | 8 | 100.0 | 100.0 | 100.0 |" in table
    assert "| ID-Pose (full) | all | 100.0 | 100.0 | 100.0 |" in table
    assert "| random poses | all |" in table and report["random_baseline"]["guesses_per_pair"] == 200
    assert report["random_baseline"]["aggregates"]["all"]["rot_acc_30"] < 0.2
    for sample in (0, 1):
        image = cv2.imread(str(out / f"cameras_{sample}.png"))
        assert image is not None and image.shape[0] > 100


def test_an_estimate_names_its_views_whose_masks_touch_the_border():
    views = [{"touches_border": flag} for flag in (False, True, True)]
    assert border_views({"views": [4, 7, 9], "details": {"views": views}}) == [7, 9]
    assert border_views({"views": [4, 7], "details": {}}) is None  # an estimate that reports no masks


def test_node_values_follow_the_node_parameters():
    values = node_values("fast", "naive", ["refine_steps_per_view=7", "adjust_lr=0.5"])
    assert values["variant"] == "naive" and values["refine_steps_per_view"] == 7 and values["adjust_lr"] == 0.5
    assert values["probe_batch"] == SolverConfig.preset("fast").probe_batch and values["preset"] == "fast"
    with pytest.raises(ValueError, match="expected NAME=VALUE"):
        node_values("default", None, ["probe_t=0.3"])  # not a node parameter
    with pytest.raises(ValueError, match="takes a int"):
        node_values("default", None, ["keep_top=many"])
    with pytest.raises(ValueError, match="keep_top"):
        node_values("default", None, ["keep_top=0"])
    assert node_values("default", None, [], image_size=64)["image_size"] == 64
    with pytest.raises(ValueError, match="image-size"):
        node_values("default", None, [], image_size=4)


@pytest.mark.slow
def test_offline_and_replay_modes_agree(tmp_path, demo_bag, oracle):
    """The command's options in both modes on the same seed; replay goes through a real estimator node over ROS.

    Both paths are handed the oracle fixture as their model (no real model is fast here); the EstimatePoses
    action and its result are the node's own.
    """
    common = [str(demo_bag), "--samples", "1", "--seed", "1", "--n", "2", "4", "--preset", "fast", "--device", "cpu",
              "--image-size", "128"]
    common += [x for item in ORACLE_SOLVER for x in ("--solver-param", item)]
    reports = {}
    for mode in ("offline", "replay"):
        args, protocol = evaluate_bag.parse_args([*common, "--mode", mode, "--out", str(tmp_path / mode)])
        estimator = estimators.make_estimator(estimator_options(args), predictor=oracle)
        try:
            run = bag_evaluation.evaluate_bag(args.bag, estimator, ground_truth_options(args), protocol,
                                              show_progress=False)
        finally:
            estimator.close()
        write_report(args.out, run)
        reports[mode] = json.loads((tmp_path / mode / "report.json").read_text())
    offline, replay = reports["offline"], reports["replay"]
    assert replay["mode"] == "replay" and offline["picks"] == replay["picks"]
    assert replay["model"]["node"].endswith("/idpose_estimator") and replay["model"]["device"] == "cpu"
    assert offline["model"] == {"model_path": "", "device": "cpu", "precision": "auto"}
    assert offline["node_parameters"]["image_size"] == replay["node_parameters"]["image_size"] == 128
    assert len(offline["pairs"]) == len(replay["pairs"]) == 1 + 3
    for a, b in zip(offline["pairs"], replay["pairs"]):
        assert (a["sample"], a["n"], a["anchor_view"], a["view"]) == (b["sample"], b["n"], b["anchor_view"], b["view"])
        np.testing.assert_allclose(a["pred_rel_sph"], b["pred_rel_sph"], atol=1e-9)
        assert a["rot_err_deg"] == pytest.approx(b["rot_err_deg"], abs=1e-6)
        assert a["pos_err"] == pytest.approx(b["pos_err"], abs=1e-9)
        assert a["score"] == pytest.approx(b["score"], rel=1e-6)  # the action result carries it as float32
        assert a["ambiguous"] == b["ambiguous"]
    for group in offline["aggregates"]:
        for key in ("rot_acc_15", "rot_acc_30", "pos_acc_0.2", "pairs"):
            assert offline["aggregates"][group][key] == replay["aggregates"][group][key]
    assert offline["aggregates"]["all"]["rot_acc_15"] == 1.0


def copy_with_transparent_view(source, out, blank_index: int) -> None:
    """Copy the bag, making the ``blank_index``-th image fully transparent (nothing to cut out: implausible)."""
    with AnyReader([source], default_typestore=TYPESTORE) as reader, BagWriter(out, "sqlite3") as bag:
        images = 0
        for connection, stamp, raw in reader.messages():
            if connection.topic == IMAGE_TOPIC:
                if images == blank_index:
                    image = TYPESTORE.deserialize_cdr(raw, connection.msgtype)
                    pixels = image.data.reshape(image.height, image.width, 4).copy()
                    pixels[..., 3] = 0
                    raw = TYPESTORE.serialize_cdr(dataclasses.replace(image, data=pixels.ravel()), connection.msgtype)
                images += 1
            bag.write(connection.topic, connection.msgtype, stamp, raw)


def test_an_implausible_view_fails_its_estimates_only(tmp_path, demo_bag, oracle):
    """Every estimate holding the transparent view is recorded as failed, with the reason; the others are scored,
    the report lists the failures, and the command says so (exit 0 while something was scored)."""
    protocol = EvaluationProtocol(samples=2, seed=0, view_counts=(2, 4))
    views = read_views(demo_bag, GroundTruthOptions(IMAGE_TOPIC))
    tasks = bag_evaluation.plan_bag(views, GroundTruthOptions(IMAGE_TOPIC), protocol)
    blank = tasks[0].pick[1]  # the first pick's second view: both of its estimates hold it
    copy_with_transparent_view(demo_bag, tmp_path / "bag", blank)  # every image is a view: ids are indices
    estimator = OfflineEstimator(oracle, ORACLE_OPTIONS.node_values())
    run = bag_evaluation.evaluate_bag(tmp_path / "bag", estimator, GroundTruthOptions(IMAGE_TOPIC), protocol,
                                    show_progress=False)
    holding = [(t.sample, t.n) for t in tasks if blank in t.pick[:t.n]]
    assert holding and len(holding) < len(tasks)
    assert [(f["sample"], f["n"]) for f in run.failures] == holding
    assert all(f"view {f['views'].index(blank)}: no object found" in f["error"] for f in run.failures)
    assert [(e["sample"], e["n"]) for e in run.estimates] == [(t.sample, t.n) for t in tasks
                                                              if (t.sample, t.n) not in holding]
    assert run.aggregates["all"]["rot_acc_15"] == 1.0
    write_report(tmp_path / "out", run)
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert [f["views"] for f in report["failed_estimates"]] == [f["views"] for f in run.failures]
    assert "## Failed estimates (not scored)" in (tmp_path / "out" / "report.md").read_text()


def test_a_pool_with_fewer_pairs_than_samples_says_so():
    sentence = picks_sentence(3, EvaluationProtocol(samples=5, seed=1), 3, 3)
    assert sentence == ("3 picks of 3 views (seed 1), not the 5 requested: 3 usable views hold only 3 different "
                        "pairs, and no pair is scored twice")
    assert "requested" not in picks_sentence(5, EvaluationProtocol(samples=5), 8, 12)
