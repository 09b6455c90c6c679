"""``lunaris predict FILE``: the Monte Carlo from a rover file, in the tool's own process."""

from __future__ import annotations

import json
import subprocess

import pytest

from common.messages import BadInput, PredictionRequest, decode_parameters
from lunaris.predict import format_prediction
from tests.harness import ROOT, ROVERS, lunaris_cmd

pytestmark = pytest.mark.timeout(120)


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(lunaris_cmd("predict", *args), capture_output=True, text=True, cwd=ROOT,
                          timeout=110)


def test_predict_from_a_file_prints_percentiles():
    done = run(str(ROVERS / "bc18650.yaml"), "--hours", "1", "--samples", "100", "--seed", "1")
    assert done.returncode == 0, done.stderr
    assert "bc18650, from" in done.stdout and "time to empty" in done.stdout
    assert "soc at 1:00:00" in done.stdout


def test_predict_from_a_file_as_json_is_the_prediction_payload():
    # The reference cell at 8 W empties in about 3360 s (ProgPy's BatteryCircuit: 3362 s);
    # 2 % capacity and 10 % resistance uncertainty spread it by a few per cent.
    done = run(str(ROVERS / "bc18650.yaml"), "--hours", "1.5", "--samples", "200", "--seed", "2",
               "--json")
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    tte = answer["time_to_empty_s"]
    assert 3150 < tte["p05"] < tte["p50"] < tte["p95"] < 3600
    assert answer["samples"] == 200 and answer["horizon_s"] == pytest.approx(5400.0)
    assert answer["soc_at_horizon"]["p95"] < 0.1


def test_bad_arguments_and_files_are_refused(tmp_path):
    assert run().returncode == 2  # neither a file nor a rover
    bad = run(str(ROVERS / "mapp.yaml"), "--samples", "0")
    assert bad.returncode == 1 and "--samples" in bad.stderr
    broken = tmp_path / "broken.yaml"
    broken.write_text("rover: [")
    gone = run(str(broken))
    assert gone.returncode == 2 and "not valid YAML" in gone.stderr
    both = run(str(ROVERS / "mapp.yaml"), "--rover", "mapp-1")
    assert both.returncode == 2 and "one of them" in both.stderr


def test_query_parameters_decode_strictly():
    assert decode_parameters("", PredictionRequest) == PredictionRequest()
    assert decode_parameters("hours=2.5;samples=300;seed=4", PredictionRequest) == \
        PredictionRequest(hours=2.5, samples=300, seed=4)
    assert decode_parameters("hours=2&samples=10", PredictionRequest).samples == 10
    for bad, says in [("hours=0", "hours"), ("samples=1.5", "samples"), ("x=1", "x"),
                      ("hours=inf", "finite"), ("=3", "name=value")]:
        with pytest.raises(BadInput, match=says):
            decode_parameters(bad, PredictionRequest)


def test_the_printout_says_not_within_where_a_share_does_not_empty():
    from common.messages import Percentiles, Prediction
    p = Prediction(t_s=60.0, horizon_s=7200.0, samples=10,
                   time_to_empty_s=Percentiles(p05=3600.0, p50=None, p95=None),
                   soc_at_horizon=Percentiles(p05=0.0, p50=0.01, p95=0.2), computed_in_s=0.5,
                   step_s=1.0, notes=["no load fault assumed"])
    text = format_prediction(p, "x")
    assert "1:00:00" in text and text.count("not within") == 2 and "note: no load fault" in text
