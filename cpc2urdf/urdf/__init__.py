"""The user's URDF: read (rules, tree, CPC form), export, write back, report, and load in Pinocchio."""
