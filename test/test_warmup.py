"""The refit's compiled kernels: filled into numba's cache ahead of the first refit, loaded after."""

import json
import os
import subprocess
import sys
from pathlib import Path

# A process that says whether the kernels are cached before it starts, warms the online core up, then
# (given a bag) runs it over the bag's first 200 s, and says, per kernel, how many of its compilations
# numba found in its cache (hits) and how many it compiled (misses).
WARM_UP_AND_COUNT = """
import json
import sys
from numba.core.registry import CPUDispatcher
from ship_ident.estimators import innovations, shooting
from ship_ident.io.files import read_samples
from ship_ident.model import integrate, linear_step
from ship_ident.online.config import OnlineConfig
from ship_ident.online.identifier import OnlineIdentifier, run_schedule
from ship_ident.online.warmup import kernels_cached, warm_up

cached_before = kernels_cached()
warm_up()
for bag in sys.argv[1:]:
    samples = [s for s in read_samples(bag) if s.time < 200.0]
    records = list(run_schedule(OnlineIdentifier(OnlineConfig()), samples))
    assert any(r.new_estimate for r in records)
counts = {}
for module in (integrate, linear_step, innovations, shooting):
    for name, kernel in vars(module).items():
        if isinstance(kernel, CPUDispatcher):
            counts[module.__name__ + "." + name] = [sum(kernel.stats.cache_hits.values()),
                                                    sum(kernel.stats.cache_misses.values())]
print(json.dumps({"cached_before": cached_before, "cached_after": kernels_cached(), "counts": counts}))
"""


def _warm_up_in_a_fresh_process(cache: Path, *bags: str) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    done = subprocess.run(
        [sys.executable, "-c", WARM_UP_AND_COUNT, *bags],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_first_start_compiles_the_usv_refit_kernels_once_and_the_next_start_loads_them(tmp_path):
    """With an empty cache (a fresh install) the warm-up compiles the free-run integrator, the exact
    step of the models without forcing terms, the innovation filter and a long window's sparse normal
    equations and writes them to the cache;
    the next start finds every one there (``kernels_cached``: a node starts no warm-up child then),
    and neither it nor the refits of a USV's bag after it compile any."""
    first_run = _warm_up_in_a_fresh_process(tmp_path)
    assert not first_run["cached_before"] and first_run["cached_after"]
    first = first_run["counts"]
    assert first["ship_ident.model.integrate.simulate_kernel"][1] >= 1
    assert first["ship_ident.estimators.innovations._whiten_blocks"][1] >= 1
    assert first["ship_ident.model.linear_step.simulate_linear_kernel"][1] >= 1
    assert first["ship_ident.estimators.shooting._sparse_normal_equations"][1] >= 1
    assert any(tmp_path.rglob("*simulate_kernel*.nbi")) and any(tmp_path.rglob("*_whiten_blocks*.nbc"))
    second_run = _warm_up_in_a_fresh_process(tmp_path, str(Path(__file__).parents[1] / "bags" / "demo_seed001.mcap"))
    assert second_run["cached_before"]
    second = second_run["counts"]
    assert all(misses == 0 for _, misses in second.values()), second
    assert second["ship_ident.model.integrate.simulate_kernel"][0] >= 1
    assert second["ship_ident.estimators.innovations._whiten_blocks"][0] >= 1
    assert second["ship_ident.model.linear_step.simulate_linear_kernel"][0] >= 1
