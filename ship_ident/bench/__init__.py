"""Benchmarks of the identification engine, run by ``ship-ident bench NAME``.

A benchmark is a module in this package that calls ``register`` at import
with its name, a one-line description, ``run(quick: bool) -> dict`` (a
JSON-ready result; progress goes to stderr) and ``render(result) -> str``
(the printed tables). A benchmark that draws figures registers with
``plots=True``; its ``run`` then takes ``plot_dir`` (``ship-ident bench NAME
--plot-dir DIR``). A benchmark that can draw its recordings from several generators registers
them (``generators``); its ``run`` then takes ``generator`` (``--generator NAME``).
``benchmarks()`` imports every module here, so adding a
benchmark means adding one module and nothing else. A benchmark with counts of its own (e.g. how
many trips of a second kind to draw) registers them as ``options`` (``Option``: ``--flag N``);
its ``run`` then takes each one given as a keyword.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Option:
    """A count a benchmark takes beside ``--count``: ``--{flag} N`` on the command line, ``run``'s
    keyword ``flag`` with dashes as underscores; ``help`` says what it counts and its default."""

    flag: str
    help: str

    @property
    def keyword(self) -> str:
        return self.flag.replace("-", "_")


@dataclass(frozen=True)
class Benchmark:
    name: str
    description: str
    run: Callable[..., dict]
    render: Callable[[dict], str]
    plots: bool = False
    randomised: bool = False
    generators: tuple[str, ...] = ()  # the recordings' generators ``run`` takes as ``generator`` (the first: default)
    options: tuple[Option, ...] = ()  # counts ``run`` takes beside ``count``


_REGISTRY: dict[str, Benchmark] = {}
# modules here that are no benchmark
HELPERS = {"crb", "common", "mmg", "peer_models", "peer_experiments", "peer_rendering"}


def register(
    name: str,
    description: str,
    run: Callable[..., dict],
    render: Callable[[dict], str],
    plots: bool = False,
    randomised: bool = False,
    generators: tuple[str, ...] = (),
    options: tuple[Option, ...] = (),
) -> None:
    _REGISTRY[name] = Benchmark(name, description, run, render, plots, randomised, generators, options)


def benchmarks() -> dict[str, Benchmark]:
    """All registered benchmarks by name (imports every benchmark module of the package)."""
    for module in pkgutil.iter_modules(__path__):
        if module.name not in HELPERS:
            importlib.import_module(f"{__name__}.{module.name}")
    return dict(sorted(_REGISTRY.items()))


def fresh_seed() -> int:
    """A seed drawn from the operating system's entropy (printed by the caller for replay)."""
    return int(np.random.SeedSequence().entropy % 2**32)


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)
