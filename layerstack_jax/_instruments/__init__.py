"""What instruments read: the geometry interfaces and parse_geometry (geometry), the
spectrophotometers — the integrating sphere (sphere), 45°/0° and BRDF (directional), specular
readings (specular) and the parts they share (optical_parts) —, the fixed optics of a measurement
(optics) and the parts of non-ideal instruments (instrument), ellipsometry (ψ/Δ, N, C, S and
their averages: ellipsometry) and the ellipsometer that reads them (the Ellipsometric geometry:
ellipsometer), polarimetry (polarized BRDF and Mueller matrices), batched prediction in bounded
memory (batched) and the colour of a spectrum (colour).

Imports the floors below (_base, _kernels, _media, _stacks); never _appearance or _files.
"""

# the spectrophotometers register with parse_geometry in this order, before the ellipsometer
from . import sphere as sphere  # noqa: I001  (registration order)
from . import directional as directional
from . import specular as specular
