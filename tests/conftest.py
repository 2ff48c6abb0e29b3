import os

os.environ.setdefault("CPC2URDF_PROGRESS", "0")
os.environ.setdefault("MPLBACKEND", "Agg")
