"""Figures, tables and exports of a run directory."""
