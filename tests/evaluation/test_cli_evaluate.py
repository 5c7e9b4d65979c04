"""``roadsynth evaluate`` end to end: atomic output folder, meta.json, exit code 2 on bad input."""

from __future__ import annotations

import json

from pipeline.stages.cli import main

GT = {"images": [{"id": 1}], "categories": [{"id": 3, "name": "car"}],
      "annotations": [{"id": 1, "image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10], "area": 100.0,
                       "iscrowd": 0}]}


def test_cli_writes_outputs(tmp_path):
    (tmp_path / "gt.json").write_text(json.dumps(GT))
    (tmp_path / "res.json").write_text(json.dumps([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10],
                                                    "score": 0.9}]))
    out = tmp_path / "eval"
    rc = main(["evaluate", "--gt", str(tmp_path / "gt.json"), "--detections", str(tmp_path / "res.json"),
               "--out", str(out), "--iou", "0.5", "0.7", "--metrics", "table,coco,errors"])
    assert rc == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert [r["iou"] for r in metrics["table"]["rows"] if r["class"] == "all" and r["group"] == "all"] == [0.5, 0.7]
    assert json.loads((out / "meta.json").read_text())["stage"] == "evaluate"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eval", "gt.json", "res.json"]  # no temporaries


def test_cli_bad_input_exits_2_and_leaves_nothing(tmp_path, capsys):
    (tmp_path / "gt.json").write_text(json.dumps(GT))
    (tmp_path / "res.json").write_text(json.dumps([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10]}]))
    out = tmp_path / "eval"
    rc = main(["evaluate", "--gt", str(tmp_path / "gt.json"), "--detections", str(tmp_path / "res.json"),
               "--out", str(out)])
    assert rc == 2
    assert "results[0]: missing field 'score'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gt.json", "res.json"]


def test_png_plots_and_matplotlib_only_when_asked(tmp_path):
    import subprocess
    import sys

    from tests.conftest import REPO

    (tmp_path / "gt.json").write_text(json.dumps(GT))
    (tmp_path / "res.json").write_text(json.dumps([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10],
                                                    "score": 0.9}, {"image_id": 1, "category_id": 44,
                                                                    "bbox": [0, 0, 5, 5], "score": 0.4}]))
    script = ("import sys; from pipeline.stages.cli import main; rc = main(sys.argv[1:]); "
              "print(rc, 'matplotlib' in sys.modules)")
    for flag, name in (([], "plain"), (["--png"], "png")):
        args = ["evaluate", "--gt", str(tmp_path / "gt.json"), "--detections", str(tmp_path / "res.json"),
                "--out", str(tmp_path / name), "--metrics", "coco", *flag]
        run = subprocess.run([sys.executable, "-c", script, *args], cwd=REPO, capture_output=True, text=True,
                             check=True, env={"PYTHONPATH": str(REPO), "PATH": ""})
        assert run.stdout.split() == ["0", str(bool(flag))]
        assert (tmp_path / name / "plots" / "coco_pr.csv").is_file()
        assert (tmp_path / name / "plots" / "coco_pr.png").is_file() == bool(flag)
        # the COCO-80 detection of category 44 (bottle), which the GT lacks: one log line, counted by id
        assert "1 detections of categories the ground truth lacks are not scored (by category id: {44: 1})" \
            in run.stderr
        ignored = json.loads((tmp_path / name / "metrics.json").read_text())["ignored"]
        assert ignored["detections_by_category_not_in_gt"] == {"44": 1}


def test_cli_realism_task(tmp_path, capsys):
    import cv2
    import numpy as np

    gt = {**GT, "images": [{"id": 1, "file_name": "1.png", "condition": "fog"}],
          "annotations": [{**GT["annotations"][0], "bbox": [0, 0, 20, 40], "track_id": 4, "distance_m": 30.0}]}
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "1.png"), np.zeros((60, 60, 3), np.uint8))
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    (tmp_path / "res.json").write_text("[]")
    args = ["evaluate", "--task", "realism", "--gt", str(tmp_path / "gt.json"), "--detections",
            str(tmp_path / "res.json"), "--score-threshold", "0.3"]
    assert main([*args, "--out", str(tmp_path / "realism")]) == 0
    out = tmp_path / "realism"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["distance"]["visibility_m"] == {"fog": 80.0}  # the fog condition's config
    assert metrics["missed_objects"]["vehicles"]["missed"] == 1 and (out / "missed_vehicles.png").is_file()
    assert json.loads((out / "meta.json").read_text())["config"]["task"] == "realism"
    assert main([*args, "--out", str(tmp_path / "other"), "--iou", "0.7"]) == 2
    assert "--iou apply to --task detection only, not realism" in capsys.readouterr().err
    assert main(["evaluate", "--gt", str(tmp_path / "gt.json"), "--detections", str(tmp_path / "res.json"),
                 "--out", str(tmp_path / "third"), "--images", str(tmp_path / "images")]) == 2
    assert "--images applies to --task realism only" in capsys.readouterr().err
