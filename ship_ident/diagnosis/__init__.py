"""Diagnosis: where a model and the measurements part, which effect is missing, offline and on board."""
