"""nurbscnc: CNC interpreter and toolpath compiler (NURBS + PH-quintic look-ahead)."""

__version__ = "0.1.0"
