"""Evaluation against reference poses (a layer beside ``io``: core, numpy, scipy and evo only)."""
