"""Compile the numeric kernels of a refit before the first refit needs them.

The free-run integrator and the innovation filter are numba kernels compiled on their first call
and kept in numba's on-disk cache (``cache=True``, next to the modules, or in ``NUMBA_CACHE_DIR``).
Right after an install that cache is empty, and a boat's first refit would spend about 13 s
compiling. ``warm_up`` runs the online core, as configured, over a short simulated manoeuvre: every
kernel a refit, a change watch and a profile of the cost calls (a long window's sparse normal
equations among them) is compiled and cached with the very
argument types they get on board, and the exact step of the models linear in their state, which the
diagnosis's linear candidates on a ship run on. With the cache filled, it loads them in well under a second.

The node runs it at start in a child process at low priority (``warm_up_quietly``; the window
fills meanwhile, and the node's first refit loads what it cached) unless ``kernels_cached`` finds
every kernel compiled already; ``make setup`` runs it once after installing
(``python -m ship_ident.online.warmup``).
"""

from __future__ import annotations

import signal
import time
from dataclasses import replace

import numpy as np
from scipy import sparse

from ..estimators import innovations, shooting
from ..estimators.shooting import normal_equations
from ..model import integrate, linear_step
from ..model.simulator import simulate
from ..model.structure import EXACT_STEP_SUBSTEPS, Structure
from .config import OnlineConfig
from .identifier import OnlineIdentifier, run_schedule
from .samples import dataset_samples

# s of simulated data: a first fit at WARM_UP_FIRST_FIT s, then refits (their change watches between
# them) on a growing window
WARM_UP_SECONDS = 40.0
WARM_UP_FIRST_FIT = 25.0
# The kernels a refit calls from Python (the ones they call are compiled into them)
ENTRY_KERNELS = (
    integrate.simulate_kernel,
    linear_step.simulate_linear_kernel,
    innovations._whiten_blocks,
    innovations._whiten_blocks_rows,
    shooting._sparse_normal_equations,
    shooting._same_columns,
)


def kernels_cached() -> bool:
    """Whether numba's cache holds each entry kernel compiled from these sources for this machine.

    Then a warm-up has nothing to compile: a process only loads them (well under a second). The
    check reads each kernel's cache index as numba's own loading does (numba has no public call
    for it): an index written for other sources, another numba or another processor does not
    count, and anything that cannot be read says no (the warm-up then runs, as without the check).

    Returns
    -------
    bool
        True when every entry kernel has a cached version usable here.
    """
    try:
        for kernel in ENTRY_KERNELS:
            cache = kernel._cache
            here = cache._index_key(None, kernel.targetctx.codegen())[1:]  # (machine, code hashes)
            if not any(key[1:] == here for key in cache._cache_file._load_index()):
                return False
    except Exception:  # numba's internals moved: warm up, as without the check
        return False
    return True


def warm_up(config: OnlineConfig | None = None) -> float:
    """Run the online core with ``config`` (the default configuration when None) over
    WARM_UP_SECONDS of a simulated mixed manoeuvre, sampled at its ``sample_time``, so that the
    kernels its refits call are compiled (or loaded from numba's cache); returns the wall time
    it took (s). Nothing of it is kept: the caller's identifier is not touched."""
    started = time.perf_counter()
    config = replace(
        config or OnlineConfig(),
        window_length=WARM_UP_SECONDS,
        min_window_length=WARM_UP_FIRST_FIT,
        diagnosis_period=0.0,
        speed_topic="",
    ).validate()
    dataset = simulate("mixed", duration=WARM_UP_SECONDS, sample_time=config.sample_time, seed=0).dataset
    for _ in run_schedule(OnlineIdentifier(config), dataset_samples(dataset)):
        pass
    # a model linear in its state with a pole the samples cannot resolve (the diagnosis's linear
    # candidates on a ship) runs on a kernel of its own, the exact step (``model.linear_step``)
    bare = Structure(config.model)
    params = {n: bare.parameter(n).initial for n in bare.parameter_names}
    bare.simulate(params, dataset, substeps=EXACT_STEP_SUBSTEPS)
    # a window of more shooting intervals than SPARSE_INTERVALS (a ship's ten minutes) keeps its
    # Jacobian sparse, and its search steps sum their normal equations in a kernel of their own
    normal_equations(sparse.csr_matrix(np.eye(2)), np.zeros(2))
    return time.perf_counter() - started


def warm_up_quietly() -> None:
    """The node's warm-up child: ``warm_up`` with the default configuration, deaf to Ctrl-C.

    The kernels' argument types do not depend on the configuration. A terminal's Ctrl-C reaches the
    whole process group: the child leaves it to the node, which ends it.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    warm_up()


if __name__ == "__main__":
    print(f"ship_ident refit kernels ready (compiled, or loaded from the cache) in {warm_up():.1f} s")
