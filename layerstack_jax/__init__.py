"""layerstack_jax — light in layered coatings, in JAX.

Coherent thin films (Rouard/Airy recursion), thick incoherent absorbing layers (Beer's law with
Fresnel multiple reflections per polarization), any mix of the two, over a specular substrate or
a Lambertian background, for integrating-sphere, radiance-detector, BRDF and specular
geometries; jit-, vmap- and grad-compatible throughout.

Units: wavelengths and thicknesses in nm, absorption coefficients α in 1/nm, angles in radians in
functions and degrees in geometry objects. Index convention n + ik with k ≥ 0 (time dependence
exp(−iωt)). The package never changes ``jax_enable_x64``: enable float64 yourself for
interference-grade accuracy (see README, "Precision").
"""

from ._fresnel import fresnel_amplitudes as fresnel_amplitudes
from ._fresnel import normal_wavevector as normal_wavevector
from ._geometry import BRDF as BRDF
from ._geometry import Diffuse as Diffuse
from ._geometry import Directional as Directional
from ._geometry import Geometry as Geometry
from ._geometry import Response as Response
from ._geometry import Specular as Specular
from ._geometry import Sphere as Sphere
from ._geometry import diffuse as diffuse
from ._geometry import invert_background as invert_background
from ._geometry import parse_geometry as parse_geometry
from ._geometry import reflectance as reflectance
from ._geometry import specular as specular
from ._materials import Cauchy as Cauchy
from ._materials import Index as Index
from ._materials import Material as Material
from ._materials import Sellmeier as Sellmeier
from ._materials import Tabulated as Tabulated
from ._quadrature import DEFAULT_NODES as DEFAULT_NODES
from ._quadrature import hemispherical_rule as hemispherical_rule
from ._stack import LambertianBackground as LambertianBackground
from ._stack import Layer as Layer
from ._stack import Stack as Stack
from ._stack import Substrate as Substrate
from ._stack import TabulatedSpectrum as TabulatedSpectrum
from ._validate import LayerstackError as LayerstackError
from .io import load_fit_stack as load_fit_stack
from .io import load_stack as load_stack
from .io import parse_wavelengths as parse_wavelengths
from .io import read_csv_columns as read_csv_columns
from .io import read_spectra_csv as read_spectra_csv
from .io import save_spectra_csv as save_spectra_csv
from .io import stack_from_dict as stack_from_dict
from .io import stack_to_dict as stack_to_dict

__version__ = "0.1.0"
