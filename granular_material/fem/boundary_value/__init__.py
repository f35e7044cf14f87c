"""Boundary-value problems: meshes, named boundaries, conditions on them and their loading,
initial stress states, the forces and displacements boundaries carry, and the biaxial
specimen with its one-element version.
"""
