"""Datasets of facial shapes and what is made of them: `dataset` (`Dataset`: shapes, UVs,
polygons; read from OBJ, glTF, `.npz`), `augment` (in-betweens) and `deform` (deformation
transfer and ARAP on the mesh Laplacian)."""
