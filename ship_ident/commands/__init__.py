"""Subcommands of ship-ident, one module each.

``SUMMARIES`` holds each command's one-line help, so that ``ship-ident --help`` (and a usage error
before the command) lists them without importing the command modules and the numeric core.
"""

SUMMARIES = {
    "simulate": "simulate a manoeuvre and write it as a bag or CSV",
    "identify": "identify a Nomoto (or 3-DOF) model from bags or CSV files",
    "compare": "run a saved model free on other data",
    "replay": "run the online identifier over a bag, faster than real time",
    "play": "publish a bag's topics live with /clock",
    "diagnose": "find where the model fails and which physical effect it misses",
    "bench": "run a benchmark of the estimators",
}
