"""Adapters between files and the core: bags and CSV, strict JSON, bag replay, fleet re-identification."""
