"""Plane geometry over (N, 2) arrays (plane) and near pairs of points (pairs). Import from the defining
module (reconswarm.geometry.plane, reconswarm.geometry.pairs)."""
