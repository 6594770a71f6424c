"""Fleet replay: many bags of two vessels, --jobs 2 and a local Dask cluster give the same table."""

import argparse
import csv
from pathlib import Path

import pytest
from conftest import once_per_run

from ship_ident.cli import build_parser, main
from ship_ident.commands.common import topics_from_args
from ship_ident.commands.replay import config_from_args
from ship_ident.io.files import write_simulation
from ship_ident.io.fleet import FleetError, add_fleet_arguments, run_fleet, vessel_of
from ship_ident.model.simulator import simulate

pytestmark = pytest.mark.slow  # a fleet of bags, a local dask cluster

TRUE_K = {"alpha": 0.5883, "bravo": 0.40}


def write_bags(root: Path) -> None:
    """Two trips of each vessel in TRUE_K, 200 s each, in ``root / VESSEL / tripN.mcap``."""
    count = 0
    for vessel, k in TRUE_K.items():
        (root / vessel).mkdir()
        for trip in range(2):
            write_simulation(
                simulate("mixed", duration=200.0, seed=10 * trip + count, parameters={"K": k}),
                root / vessel / f"trip{trip}.mcap",
                "mcap",
            )
            count += 1


@pytest.fixture(scope="module")
def bags(run_folder):
    """The fleet's bags, written once per run (the test workers share them)."""
    root = once_per_run(run_folder, "fleet", write_bags)
    return [str(root / vessel / f"trip{trip}.mcap") for vessel in TRUE_K for trip in range(2)]


def fleet_args(bags, *options):
    """replay's options (window, topics, ...) with the fleet options on top."""
    args = build_parser().parse_args(["replay", bags[0], "--refit-period", "10"])
    fleet = argparse.ArgumentParser()
    add_fleet_arguments(fleet)
    return fleet.parse_args(list(options), namespace=args)


def replay_fleet(args, bags):
    """What ``ship-ident replay`` does with many bags: topics and configuration from its options."""
    topics = topics_from_args(args)
    return run_fleet(args, bags, topics, config_from_args(args, topics, has_speed=True))


def read_table(path):
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def pool_rows(bags, run_folder):
    """The table of ``replay --jobs 2`` over the fleet, made once per run (the test workers share it)."""

    def replay_with_a_pool(out: Path) -> None:
        assert replay_fleet(fleet_args(bags, "--jobs", "2", "--table", str(out / "fleet.csv")), bags) == 0
        assert sorted(p.name for p in out.glob("drift_*.png")) == ["drift_alpha.png", "drift_bravo.png"]

    return read_table(once_per_run(run_folder, "pool", replay_with_a_pool) / "fleet.csv")


def test_vessel_rules():
    assert vessel_of("/data/alpha/trip0.mcap") == "alpha"
    assert vessel_of("/data/all/alpha_2024-05-01.mcap", "prefix") == "alpha"
    assert vessel_of("/data/hull-bravo/x.mcap", r"hull-(\w+)") == "bravo"
    with pytest.raises(FleetError, match="no match with a group"):
        vessel_of("/data/hull-bravo/x.mcap", r"hull-\w+")


def test_bad_fleet_options_are_one_line_and_exit_2(bags, capsys):
    assert main(["replay", bags[0], bags[1], "--jobs", "0"]) == 2
    err = capsys.readouterr().err
    assert err == "ship-ident replay: error: --jobs must be >= 1, got 0\n"
    assert main(["replay", bags[0], bags[1], "--vessel-from", "nothing-(here)"]) == 2
    assert "--vessel-from 'nothing-(here)' has no match" in capsys.readouterr().err


def test_jobs_table_has_rows_per_vessel_matching_truth(pool_rows, bags, capsys):
    assert {row["bag"] for row in pool_rows} == set(bags)
    for vessel, k in TRUE_K.items():
        mine = [row for row in pool_rows if row["vessel"] == vessel]
        assert len(mine) >= 2 * 10  # refits every 10 s from 60 s on, each an accepted estimate
        ks = sorted(float(row["K"]) for row in mine)
        assert ks[len(ks) // 2] == pytest.approx(k, rel=0.03)
        assert all(float(row["K_std"]) > 0 for row in mine)
    assert {"time", "window_start", "window_end", "T1", "T1_std", "fit_rmse_heading"} <= set(pool_rows[0])


def test_local_dask_cluster_gives_the_same_rows(pool_rows, bags, tmp_path, capsys):
    table = tmp_path / "dask.csv"
    assert replay_fleet(fleet_args(bags, "--dask", "local", "--jobs", "2", "--table", str(table)), bags) == 0
    rows = read_table(table)
    assert [(r["vessel"], r["bag"], r["time"]) for r in rows] == [(r["vessel"], r["bag"], r["time"]) for r in pool_rows]
    for mine, theirs in zip(rows, pool_rows):
        assert float(mine["K"]) == pytest.approx(float(theirs["K"]), rel=1e-9)
    assert "bags/min" in capsys.readouterr().out


def test_a_bad_bag_fails_alone(bags, tmp_path, capsys):
    broken = tmp_path / "charlie" / "broken.mcap"
    broken.parent.mkdir()
    broken.write_bytes(b"not a bag")
    assert replay_fleet(fleet_args(bags, "--table", str(tmp_path / "t.csv")), [bags[0], str(broken)]) == 1
    assert "FAILED" in capsys.readouterr().err
    assert {row["vessel"] for row in read_table(tmp_path / "t.csv")} == {"alpha"}
