"""Tabulated microfacet normal distributions (Wang et al. 2008): tables, their shadowing and
sampling data (:mod:`.table`)."""

from .table import NDFTable, from_arrays, load_ndf, sampled_table

__all__ = ["NDFTable", "from_arrays", "load_ndf", "sampled_table"]
