"""3-DOF manoeuvring model: simulator, identification, free-run prediction, training-size bench, KVLCC2,
and the command line (simulate, identify, compare --model 3dof)."""

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from ship_ident import threedof
from ship_ident.bench import training_size
from ship_ident.cli import main

DTC = threedof.VESSELS["dtc"]
PROGRAMME = (
    ("zigzag", 10, 100),
    ("zigzag", 20, 100),
    ("turning", 35, 120),
    ("zigzag", -15, 100),
    ("turning", -25, 120),
)
KVLCC2_RAW = Path(__file__).resolve().parents[2] / "shared" / "data" / "kvlcc2_marin" / "raw"
LINEAR_YN = ("v", "r", "d")


def _programme(noise):
    return [
        threedof.simulate_manoeuvre(DTC, m, a, duration=d, noise=noise, seed=i)[0]
        for i, (m, a, d) in enumerate(PROGRAMME)
    ]


def _relative_errors(estimate, truth, dof):
    terms = threedof.X_TERMS if dof == "surge" else threedof.YN_TERMS
    est, true = estimate.vector(dof), truth.vector(dof)
    return {t: abs(e - w) / abs(w) for t, e, w in zip(terms, est, true)}


def test_free_run_of_true_model_reproduces_the_simulation():
    _, truth = threedof.simulate_manoeuvre(DTC, "turning", 35, duration=60, noise=0.0)
    rerun = threedof.run_model(
        DTC.coefficients(),
        truth.time,
        truth.rudder,
        (truth.surge[0], truth.sway[0], truth.yaw_rate[0], truth.heading[0]),
    )
    for dof in threedof.DOFS:
        assert np.max(np.abs(rerun.dof(dof) - truth.dof(dof))) < 1e-12


def test_starboard_rudder_turns_to_starboard_and_zigzag_switches_on_heading():
    _, turn = threedof.simulate_manoeuvre(DTC, "turning", 35, duration=60, noise=0.0)
    assert turn.yaw_rate[-1] > 0 and turn.heading[-1] > np.radians(90)
    assert turn.surge[-1] < DTC.speed  # speed loss in the turn
    _, zigzag = threedof.simulate_manoeuvre(DTC, "zigzag", 20, duration=60, noise=0.0)
    first_switch = np.flatnonzero(np.diff(zigzag.rudder) < 0)[0]
    assert zigzag.heading[first_switch] == pytest.approx(np.radians(20), abs=np.radians(1.0))


def test_noise_free_identification_recovers_the_coefficients():
    identification = threedof.identify(_programme(0.0), DTC.length, DTC.speed, method="ols")
    truth = DTC.coefficients()
    for dof in threedof.DOFS:
        errors = _relative_errors(identification.coefficients, truth, dof)
        main = ("u", "vv", "rv", "dd") if dof == "surge" else LINEAR_YN + ("vvv", "vvr", "ddd")
        assert max(errors[t] for t in main) < 0.01, (dof, errors)
        small = {"vdd"}  # |Y_vdd| is 1/300 of |Y_v|: its column barely moves the sway and yaw accelerations
        assert max(e for t, e in errors.items() if t not in small) < 0.05, (dof, errors)


def test_noisy_identification_reports_truncation_and_std_errors():
    identification = threedof.identify(_programme(1.0), DTC.length, DTC.speed, method="tlssvm-gcv")
    truth = DTC.coefficients()
    for dof in ("sway", "yaw"):
        errors = _relative_errors(identification.coefficients, truth, dof)
        assert max(errors[t] for t in LINEAR_YN) < 0.15, (dof, errors)
    assert _relative_errors(identification.coefficients, truth, "surge")["u"] < 0.35
    for dof in threedof.DOFS:
        info = identification.info[dof]
        assert info["rule"] == "gcv" and 1 <= info["truncation"] <= info["of"]
        std = identification.coefficients.std_errors[dof]
        assert np.all(np.isfinite(std)) and np.all(std >= 0) and np.any(std > 0)
    record = identification.to_json()["coefficients"]["yaw"]["d"]
    assert record["value"] > 0 and record["std_error"] > 0


@pytest.mark.parametrize("method", ["tlssvm-gcv", "tlssvm-picard", "ols"])
def test_held_out_free_run_prediction_correlates_per_dof(method):
    identification = threedof.identify(_programme(1.0), DTC.length, DTC.speed, method=method)
    held_out, _ = threedof.simulate_manoeuvre(DTC, "zigzag", 15, duration=100, seed=99)
    metrics = threedof.prediction_metrics(held_out, threedof.predict(identification.coefficients, held_out))
    for dof in threedof.DOFS:
        assert not metrics[dof]["diverged"]
        assert metrics[dof]["r"] > 0.95, (method, dof, metrics[dof])


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="unknown 3-DOF method"):
        threedof.identify(_programme(0.0)[:1], DTC.length, DTC.speed, method="tlssvm-magic")


def test_training_size_quick_run_improves_with_set_size(tmp_path):
    figure = tmp_path / "taylor.png"
    result = training_size.run(quick=True, progress=lambda message: None, figure=str(figure))
    rows = result["methods"]["tlssvm-gcv"]["rows"]
    assert [r["size"] for r in rows] == list(training_size.QUICK_SIZES)
    smallest, largest = rows[0], rows[-1]
    assert training_size.mean_e_centred(largest) < training_size.mean_e_centred(smallest)
    assert all(largest[d]["r"] >= smallest[d]["r"] for d in threedof.DOFS)
    assert result["methods"]["tlssvm-gcv"]["plateau_size"] in training_size.QUICK_SIZES
    assert figure.stat().st_size > 10_000
    table = training_size.render(result)
    assert "adding data stops helping" in table and "SURGE R" in table and "10000" in table


@pytest.fixture(scope="module")
def kvlcc2():
    if not KVLCC2_RAW.is_dir():
        pytest.skip(f"KVLCC2 MARIN raw data not found at {KVLCC2_RAW} (shared data set absent)")
    return {
        name: threedof.load_marin_raw(str(KVLCC2_RAW / f"MARIN_FREE_KVLCC2_{name}_m.dat"))
        for name in ("zz_10", "zz_20", "zz_-20")
    }


def test_kvlcc2_loader_rotates_velocities_and_flips_rudder(kvlcc2):
    zz10 = kvlcc2["zz_10"]
    assert len(zz10) == 3844
    assert zz10.sample_time == pytest.approx(0.135264, rel=1e-4)
    assert threedof.approach_speed(zz10) == pytest.approx(7.97, abs=0.05)
    drift = np.degrees(np.arctan2(zz10.sway, zz10.surge))
    assert np.sqrt(np.mean(drift**2)) < 8.0  # body-fixed drift angle stays small
    assert zz10.surge.min() > 6.5
    execute = np.flatnonzero(np.abs(zz10.rudder - zz10.rudder[0]) > np.radians(1.0))[0]
    assert zz10.rudder[execute + 50] < 0  # the run starts to port ...
    assert zz10.yaw_rate[execute + 200] < 0  # ... and turns to port
    assert np.allclose(zz10.propeller_rate, 91.7 / 60, rtol=0.02)


def test_kvlcc2_zigzag_cross_validation(kvlcc2):
    train, test = kvlcc2["zz_20"], kvlcc2["zz_-20"]
    length = threedof.VESSELS["kvlcc2"].length
    identification = threedof.identify(train, length, threedof.approach_speed(train), method="tlssvm-gcv")
    metrics = threedof.prediction_metrics(test, threedof.predict(identification.coefficients, test))
    for dof in threedof.DOFS:
        assert not metrics[dof]["diverged"]
        assert metrics[dof]["r"] > 0.95, (dof, metrics[dof])
        assert 0.7 < metrics[dof]["std_ratio"] < 1.3


# --- the command line: simulate, identify, compare --model 3dof -------------------------------

CLI_PROGRAMME = (("zigzag10", 100), ("zigzag20", 100), ("turning", 120))
SMALL_TERMS = {"vdd", "0uu"}  # columns that barely move the sway and yaw accelerations on three manoeuvres


def run_cli(*args) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main([str(a) for a in args])
    return code, out.getvalue()


@pytest.fixture(scope="module")
def cli_programme(tmp_path_factory):
    """Three noise-free DTC manoeuvres written by ``simulate --model 3dof`` as CSV and as bags (mcap
    and rosbag2 mixed), and the truth file: ({"csv": paths, "bag": paths}, truth path)."""
    folder = tmp_path_factory.mktemp("threedof_cli")
    paths = {"csv": [], "bag": []}
    for seed, (manoeuvre, duration) in enumerate(CLI_PROGRAMME):
        for kind, name in (("csv", f"{manoeuvre}.csv"), ("bag", f"{manoeuvre}.mcap" if seed else manoeuvre)):
            code, out = run_cli(
                "simulate",
                "--model",
                "3dof",
                "--maneuver",
                manoeuvre,
                "--duration",
                duration,
                "--noise",
                "0",
                "--seed",
                seed,
                "--out",
                folder / name,
                "--truth-out",
                folder / "truth.json",
            )
            assert code == 0 and "3dof dtc" in out
            paths[kind].append(folder / name)
    return paths, folder / "truth.json"


def cli_identify(paths, *options) -> dict:
    code, out = run_cli("identify", "--model", "3dof", *paths, "--length", DTC.length, "--json", *options)
    assert code == 0
    return json.loads(out)


@pytest.mark.parametrize("kind", ["csv", "bag"])
def test_identify_3dof_on_the_command_line_recovers_the_coefficients(cli_programme, kind):
    """Noise-free CSV files / bags (velocity as TwistStamped) of three manoeuvres: OLS recovers the
    main coefficients within 1 % and the others within 5 % (measured: 0.5 % and 2.3 %)."""
    paths, truth_file = cli_programme
    record = cli_identify(paths[kind], "--reference-speed", DTC.speed, "--method", "ols")
    truth = json.loads(truth_file.read_text())["coefficients"]
    assert record["structure"] == {"model": "3dof", "effects": []} and record["method"] == "ols"
    assert record["samples"] == 1001 + 1001 + 1201
    for dof in threedof.DOFS:
        errors = {
            t: abs(record["coefficients"][dof][t]["value"] - v["value"]) / abs(v["value"])
            for t, v in truth[dof].items()
        }
        main_terms = ("u", "vv", "rv", "dd") if dof == "surge" else LINEAR_YN + ("vvv", "vvr", "ddd")
        assert max(errors[t] for t in main_terms) < 0.01, (dof, errors)
        assert max(e for t, e in errors.items() if t not in SMALL_TERMS) < 0.05, (dof, errors)
        assert record["fit"][dof]["r"] > 0.999


def test_csv_and_bag_give_the_same_3dof_model(cli_programme):
    paths, _ = cli_programme
    from_csv, from_bag = (cli_identify(paths[kind], "--truncation", "lcurve") for kind in ("csv", "bag"))
    assert from_csv["method"] == "tlssvm-lcurve" and from_csv["info"]["yaw"]["rule"] == "lcurve"
    for dof in threedof.DOFS:
        for term, value in from_csv["coefficients"][dof].items():
            assert from_bag["coefficients"][dof][term]["value"] == pytest.approx(value["value"], rel=1e-6, abs=1e-9)
    assert from_csv["coefficients"]["speed"] == pytest.approx(DTC.speed, rel=0.01)  # the approach speed


def test_compare_runs_a_3dof_model_file_free(cli_programme, tmp_path):
    paths, truth_file = cli_programme
    model = tmp_path / "model.json"
    code, _ = run_cli(
        "identify", "--model", "3dof", *paths["csv"][:2], "--length", DTC.length, "--method", "ols", "--save", model
    )
    assert code == 0
    for model_file in (model, truth_file):
        code, out = run_cli("compare", model_file, paths["bag"][2], "--json")
        assert code == 0
        fit = json.loads(out)["fit"]
        assert all(fit[dof]["r"] > 0.99 for dof in threedof.DOFS), fit
    code, out = run_cli("compare", model, paths["csv"][0])
    assert code == 0 and "free-run fit: surge RMSE" in out and "deg/s" in out


def test_bad_3dof_input_is_one_line_and_exit_2(cli_programme, tmp_path):
    paths, _ = cli_programme
    nomoto_csv = tmp_path / "nomoto.csv"
    nomoto_csv.write_text(
        "t,rudder,heading,yaw_rate,speed\n" + "".join(f"{i / 10},0.1,0.0,0.0,1.0\n" for i in range(100))
    )
    nomoto_bag = tmp_path / "nomoto.mcap"
    assert run_cli("simulate", "--maneuver", "zigzag20", "--duration", "60", "--out", nomoto_bag)[0] == 0
    csv = paths["csv"][0]
    cases = [
        (("identify", "--model", "3dof", csv), "needs --length"),
        (("identify", "--model", "3dof", csv, "--length", "4", "--effects", "cubic_yaw"), "no --effects"),
        (("identify", "--model", "3dof", csv, "--length", "4", "--method", "rwlssvm"), "tlssvm or ols"),
        (("identify", "--model", "3dof", csv, "--length", "4", "--truncation", "magic"), "invalid choice"),
        (("identify", "--model", "3dof", nomoto_csv, "--length", "4"), "no column for surge, sway"),
        (("identify", "--model", "3dof", nomoto_bag, "--length", "4"), "has no topic /usv/velocity"),
        (
            ("identify", "--model", "3dof", nomoto_bag, "--length", "4", "--velocity-topic", "/usv/rudder"),
            "expected nav_msgs/msg/Odometry or geometry_msgs/msg/TwistStamped",
        ),
        (("identify", csv, "--columns", "sway=sway_speed"), "this model reads no sway"),
        (("simulate", "--model", "3dof", "--maneuver", "random", "--out", tmp_path / "x.csv"), "zigzag10"),
        (
            ("simulate", "--model", "3dof", "--vessel", "kvlcc2", "--maneuver", "turning", "--out", tmp_path / "x.csv"),
            "vessel dtc",
        ),
        (("diagnose", csv, "--model", "3dof"), "invalid choice"),
    ]
    for args, words in cases:
        code, out, err = run_cli_with_stderr(*args)
        assert code == 2 and out == "", (args, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and words in lines[0], (args, err)


def run_cli_with_stderr(*args) -> tuple[int, str, str]:
    """``ship-ident ARGS`` in this process, argparse's exits included: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as exit_:
            code = exit_.code
    return code, out.getvalue(), err.getvalue()
