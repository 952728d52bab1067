"""What instruments read: the fixed optics of a measurement (optics), measurement geometries (geometry)
and the parts of non-ideal spectrophotometers (instrument), ellipsometry, polarimetry (polarized BRDF and
Mueller matrices), batched prediction in bounded memory (batched) and the colour of a spectrum (colour).

Imports the floors below (_base, _kernels, _media, _stacks); never _appearance or _files.
"""
