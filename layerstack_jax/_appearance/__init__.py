"""Appearance of coated objects: rough surfaces — a microfacet lobe over a conformal coating (rough),
He–Torrance boundaries (he_torrance), Hirayama's films on a rough object (coated_rough) — and the tables
renderers interpolate (render_tables).

Imports the floors below (_base, _kernels, _media, _stacks); never _instruments or _files.
"""
