"""``ship-ident simulate | identify | compare`` end to end, on real files, as a user runs them."""

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_io import BAD_INPUTS, make_bad_input

from ship_ident.cli import main
from ship_ident.estimators import make_estimator
from ship_ident.io.files import load_dataset
from ship_ident.model.dataset import join_recordings
from ship_ident.model.simulator import simulate
from ship_ident.model.structure import Structure

BAGS = Path(__file__).parents[1] / "bags"

FORMATS = {"rosbag2": "clean", "mcap": "clean.mcap", "csv": "clean.csv"}
CLEAN = ["--maneuver", "zigzag20", "--effects", "", "--noise", "0", "--duration", "300", "--seed", "3"]


def run_main(*args) -> tuple[int, str]:
    """``ship-ident ARGS`` in this process: (exit code, stdout)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main([str(a) for a in args])
    return code, out.getvalue()


@pytest.fixture(scope="module")
def clean_files(tmp_path_factory):
    """A noise-free nomoto2 zigzag simulated by the CLI in every format, and its truth file."""
    folder = tmp_path_factory.mktemp("cli")
    paths = {fmt: folder / name for fmt, name in FORMATS.items()}
    for fmt, path in paths.items():
        code, out = run_main("simulate", *CLEAN, "--out", path, "--truth-out", folder / "truth.json")
        assert code == 0 and f"({fmt}, 3001 samples" in out
    return paths, json.loads((folder / "truth.json").read_text())


@pytest.fixture(scope="module")
def ols_records(clean_files):
    """``identify --method ols --json`` of every format: {fmt: record}."""
    paths, _ = clean_files
    records = {}
    for fmt, path in paths.items():
        code, out = run_main("identify", path, "--method", "ols", "--json")
        assert code == 0
        records[fmt] = json.loads(out)
    return records


def test_identify_ols_recovers_noise_free_nomoto2(clean_files, ols_records):
    _, truth = clean_files
    assert truth["structure"] == {"model": "nomoto2", "effects": []}
    true, found = truth["parameters"], ols_records["rosbag2"]["parameters"]
    assert found["K"] == pytest.approx(true["K"], rel=0.02)
    assert effective_time_constant(found) == pytest.approx(effective_time_constant(true), rel=0.05)


def effective_time_constant(p: dict) -> float:
    """T1 + T2 - T3 (s): the first-order equivalent time constant, well determined by any fit."""
    return p["T1"] + p["T2"] - p["T3"]


def test_identify_gives_the_same_numbers_for_every_format(ols_records):
    reference = ols_records["rosbag2"]
    for fmt in ("mcap", "csv"):
        for name, value in reference["parameters"].items():
            assert ols_records[fmt]["parameters"][name] == pytest.approx(value, rel=1e-9), (fmt, name)
        assert ols_records[fmt]["fit"]["rmse_heading"] == pytest.approx(
            reference["fit"]["rmse_heading"], rel=1e-6, abs=1e-12
        )


def test_identify_json_follows_the_contract(ols_records):
    record = ols_records["mcap"]
    assert {"structure", "method", "parameters", "std_errors", "fit", "samples", "flags"} <= set(record)
    assert record["method"] == "ols" and record["samples"] == 3001
    assert list(record["parameters"]) == ["K", "T1", "T2", "T3"] == list(record["std_errors"])
    assert record["fit"]["horizon"] == "free-run"


@pytest.mark.slow
def test_identify_json_as_subprocess_prints_only_json(clean_files, ship_ident_cli, tmp_path):
    paths, _ = clean_files
    result = ship_ident_cli(
        "identify",
        paths["csv"],
        "--method",
        "ols",
        "--effects",
        "rudder_offset",
        "--json",
        "--save",
        tmp_path / "model.json",
    )
    assert result.returncode == 0, result.stderr
    record = json.loads(result.stdout)
    assert record["structure"] == {"model": "nomoto2", "effects": ["rudder_offset"]}
    assert list(record["parameters"]) == ["K", "T1", "T2", "T3", "delta_r"]
    assert json.loads((tmp_path / "model.json").read_text())["parameters"] == record["parameters"]


def test_identify_table_shows_degrees(clean_files):
    paths, _ = clean_files
    code, out = run_main("identify", paths["mcap"], "--method", "ols", "--effects", "rudder_offset")
    assert code == 0
    assert "delta_r" in out and " deg" in out and "free-run fit" in out


def test_compare_runs_a_saved_model_free_on_other_data(clean_files, tmp_path):
    paths, truth = clean_files
    model = tmp_path / "model.json"
    assert run_main("identify", paths["rosbag2"], "--method", "ols", "--save", model)[0] == 0
    other = tmp_path / "turning.csv"
    assert (
        run_main(
            "simulate", "--maneuver", "turning", "--effects", "", "--noise", "0", "--duration", "200", "--out", other
        )[0]
        == 0
    )
    code, out = run_main("compare", model, other, "--json")
    assert code == 0
    record = json.loads(out)
    assert record["fit"]["horizon"] == "free-run" and record["samples"] == 2001
    assert record["fit"]["r_heading"] > 0.999 and record["fit"]["r_yaw_rate"] > 0.99
    assert record["structure"] == truth["structure"]
    code, out = run_main("compare", model, other)
    assert code == 0 and "free-run fit" in out and "deg/s" in out


def test_bundled_demo_bag_matches_its_truth_file():
    truth = json.loads((BAGS / "demo_seed001.truth.json").read_text())
    data = load_dataset(BAGS / "demo_seed001.mcap")
    assert truth["vessel"] == "seed001" and truth["maneuver"] == "mixed"
    assert data.n_samples == 6001 and data.speed is not None
    assert data.duration == pytest.approx(truth["duration"])
    assert (BAGS / "demo_seed001.mcap").stat().st_size < 3e6


# --- bad input: exit 2, one line on stderr, nothing on stdout, no traceback ------------------


def assert_one_line_error(result, words):
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert words in lines[0] and result.stdout == ""


@pytest.mark.slow
@pytest.mark.parametrize("kind", BAD_INPUTS)
def test_identify_bad_data_exits_2_with_one_line(kind, tmp_path, clean_files, ship_ident_cli):
    paths, _ = clean_files
    bad = make_bad_input(kind, tmp_path, paths["mcap"])
    assert_one_line_error(ship_ident_cli("identify", bad, "--json"), BAD_INPUTS[kind])


@pytest.mark.slow
def test_bad_arguments_exit_2_with_one_line(tmp_path, clean_files, ship_ident_cli):
    paths, _ = clean_files
    not_a_model = tmp_path / "model.json"
    not_a_model.write_text('{"structure": {"model": "nomoto2"}}')
    straight = tmp_path / "straight.csv"
    straight.write_text("t,rudder,heading,yaw_rate\n" + "".join(f"{i / 10},0.0,0.5,0.0\n" for i in range(600)))
    cases = [
        (("identify", paths["csv"], "--method", "magic"), "unknown method"),
        (("identify", paths["csv"], "--effects", "barnacles"), "unknown effect"),
        (("identify", straight), "too little excitation"),
        (("compare", not_a_model, paths["csv"]), "not a model file"),
        (("simulate", "--maneuver", "turning", "--out", paths["csv"]), "exists already"),
        (("identify", paths["csv"], "--sample-time", "abc"), "invalid float value"),  # argparse's own
        (("diagnose", paths["csv"], "--model", "nomoto9"), "invalid choice"),
        (("replay", paths["csv"], "--no-such-option"), "unrecognized arguments"),
        (("frobnicate",), "invalid choice"),
    ]
    for args, words in cases:
        assert_one_line_error(ship_ident_cli(*args), words)


# --- several recordings, CSV columns by name -------------------------------------------------


@pytest.fixture(scope="module")
def short_runs(tmp_path_factory):
    """60-200 s manoeuvres of one plain nomoto2 vessel: a noisy zigzag (bag) and turning circle
    (CSV at 0.2 s), and a random-rudder run with realistic noise (CSV) to judge on (judged on
    noise-free data, the scatter of a 120 s fit at 3x noise is itself structure above the floor)."""
    folder = tmp_path_factory.mktemp("recordings")
    runs = {
        "zigzag": ("zigzag10", "60", "0.1", "3", folder / "zigzag.mcap"),
        "turning": ("turning", "60", "0.2", "3", folder / "turning.csv"),
        "random": ("random", "200", "0.1", "1", folder / "random.csv"),
    }
    for seed, (maneuver, duration, step, noise, path) in enumerate(runs.values(), start=11):
        code, _ = run_main(
            "simulate",
            "--maneuver",
            maneuver,
            "--effects",
            "",
            "--noise",
            noise,
            "--duration",
            duration,
            "--sample-time",
            step,
            "--seed",
            seed,
            "--out",
            path,
        )
        assert code == 0
    return {name: run[-1] for name, run in runs.items()}


def test_identify_fits_several_recordings_as_one(short_runs):
    """A bag at 0.1 s and a CSV at 0.2 s fitted together: both read at --sample-time, each its own
    recording in the JSON."""
    data = [short_runs["zigzag"], short_runs["turning"]]
    code, out = run_main("identify", *data, "--method", "rwlssvm", "--json")
    assert code == 0
    record = json.loads(out)
    assert record["data"] == [str(p) for p in data] and record["samples"] == 1202
    assert record["recordings"] == [
        {"name": str(data[0]), "start": 0, "stop": 601},
        {"name": str(data[1]), "start": 601, "stop": 1202},
    ]  # 0.2 s read at 0.1 s


def test_joint_fit_of_two_recordings_beats_either_alone():
    """Known truth: a short noisy zigzag and turning circle of one vessel, fitted alone and joined
    (each its own segment). Run free on a noise-free third manoeuvre, the joint model's yaw-rate
    error, averaged over four seeds, is below either single recording's (measured: 0.29 and
    0.30 deg/s alone, 0.13 deg/s joined)."""
    structure = Structure("nomoto2", ())
    judge = simulate("random", "seed001", (), duration=200, noise=0, seed=13).dataset
    estimator = make_estimator("rwlssvm")
    errors = {"zigzag": [], "turning": [], "joined": []}
    for seed in range(4):
        zigzag = simulate("zigzag10", "seed001", (), duration=60, noise=3, seed=seed).dataset
        turning = simulate("turning", "seed001", (), duration=60, noise=3, seed=seed + 100, sample_time=0.2).dataset
        for name, data in (("zigzag", zigzag), ("turning", turning), ("joined", join_recordings([zigzag, turning]))):
            _, yaw_rate = structure.simulate(estimator.fit(structure, data).parameters, judge)
            errors[name].append(np.sqrt(np.mean((yaw_rate - judge.yaw_rate) ** 2)))
    mean = {name: math.degrees(np.mean(values)) for name, values in errors.items()}
    print("held-out yaw-rate RMSE (deg/s):", mean)
    assert mean["joined"] < 0.7 * min(mean["zigzag"], mean["turning"])


@pytest.mark.slow
def test_compare_and_diagnose_take_several_recordings(short_runs, tmp_path):
    model = tmp_path / "model.json"
    assert run_main("identify", short_runs["zigzag"], "--method", "rwlssvm", "--save", model)[0] == 0
    code, out = run_main("compare", model, short_runs["random"], short_runs["turning"], "--json")
    assert code == 0
    record = json.loads(out)
    assert [r["name"] for r in record["recordings"]] == [str(short_runs["random"]), str(short_runs["turning"])]
    assert record["samples"] == 2001 + 601 and record["fit"]["r_yaw_rate"] > 0.9
    code, out = run_main(
        "diagnose",
        short_runs["zigzag"],
        short_runs["turning"],
        "--validate",
        short_runs["random"],
        "--validate",
        short_runs["zigzag"],
        "--workers",
        "1",
        "--json",
    )
    assert code == 0
    record = json.loads(out)
    assert record["data"] == [str(short_runs["zigzag"]), str(short_runs["turning"])]
    assert record["validate"] == [str(short_runs["random"]), str(short_runs["zigzag"])]
    assert record["verdict"] == "adequate"  # the truth is the plain model: nothing is missing
    assert not any(c["significant"] for c in record["candidates"])


@pytest.mark.slow
def test_columns_by_name_and_synonyms_on_the_command_line(clean_files, ship_ident_cli, tmp_path):
    """A public simulator's CSV (speed named surge_speed) is read without options, the mapping said
    on one stderr line; own names through --columns; an unknown column is one line and exit 2."""
    paths, _ = clean_files
    lines = paths["csv"].read_text().splitlines()
    public = tmp_path / "public.csv"
    public.write_text("\n".join(["time,delta,psi,r,surge_speed"] + lines[1:]) + "\n")
    result = ship_ident_cli("identify", public, "--method", "ols", "--json")
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip() == (
        f"ship-ident identify: {public}: reading columns t=time,rudder=delta,heading=psi,yaw_rate=r,speed=surge_speed"
    )
    assert json.loads(result.stdout)["samples"] == 3001
    canonical = ship_ident_cli("identify", paths["csv"], "--method", "ols", "--json")
    assert canonical.returncode == 0 and canonical.stderr == ""  # canonical names: nothing said
    own = tmp_path / "own.csv"
    own.write_text("\n".join(["clock,helm,compass,gyro,log"] + lines[1:]) + "\n")
    code, out = run_main(
        "identify",
        own,
        "--method",
        "ols",
        "--json",
        "--columns",
        "t=clock,rudder=helm,heading=compass,yaw_rate=gyro,speed=log",
    )
    assert code == 0 and json.loads(out)["parameters"] == json.loads(canonical.stdout)["parameters"]
    for command, args, words in [
        ("identify", (own, "--columns", "rudder=rudder_cmd"), "has no column 'rudder_cmd'"),
        ("diagnose", (own,), "no column for t"),
        ("replay", (paths["csv"], "--columns", "sped=speed"), "unknown role 'sped'"),
    ]:
        assert_one_line_error(ship_ident_cli(command, *args), words)
    assert_one_line_error(ship_ident_cli("compare", own, own, "--columns", "rudder=x"), "not a model file")
