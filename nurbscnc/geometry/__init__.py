"""Geometry: path segments, NURBS evaluation, PH quintics."""
