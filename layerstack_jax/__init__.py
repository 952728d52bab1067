"""layerstack_jax — light in layered coatings, in JAX.

Coherent thin films (Rouard/Airy recursion), thick incoherent absorbing layers (Beer's law with
Fresnel multiple reflections per polarization), any mix of the two, over a specular substrate or
a Lambertian background, for integrating-sphere, radiance-detector, BRDF and specular
geometries; jit-, vmap- and grad-compatible throughout.

Units: wavelengths and thicknesses in nm, absorption coefficients α in 1/nm, angles in degrees at
every public surface (functions and geometry objects; :func:`specular` also takes ``angle_rad=``). Index convention n + ik with k ≥ 0 (time dependence
exp(−iωt)). The package never changes ``jax_enable_x64``: enable float64 yourself for
interference-grade accuracy (see README, "Precision").
"""

from ._batched import MEMORY_FRACTION as MEMORY_FRACTION
from ._batched import MemoryBudget as MemoryBudget
from ._batched import memory_budget as memory_budget
from ._batched import predict as predict
from ._coated_rough import CoatedRough as CoatedRough
from ._coated_rough import coated_rough as coated_rough
from ._colour import OBSERVERS as OBSERVERS
from ._colour import VISIBLE_RANGE_NM as VISIBLE_RANGE_NM
from ._colour import ColourSpace as ColourSpace
from ._colour import delta_e_2000 as delta_e_2000
from ._colour import delta_e_ab as delta_e_ab
from ._colour import srgb_encode as srgb_encode
from ._colour import xyz_to_lab as xyz_to_lab
from ._colour import xyz_to_xyy as xyz_to_xyy
from ._cubes import as_cube as as_cube
from ._cubes import open_cube as open_cube
from ._cubes import read_envi as read_envi
from ._cubes import read_netcdf as read_netcdf
from ._cubes import read_npy as read_npy
from ._cubes import read_zarr as read_zarr
from ._cubes import write_zarr_cube as write_zarr_cube
from ._custom_types import RealLike as RealLike
from ._database import DatabaseFormula as DatabaseFormula
from ._database import database_version as database_version
from ._database import material as material
from ._database import material_sources as material_sources
from ._effective_medium import Bruggeman as Bruggeman
from ._effective_medium import Looyenga as Looyenga
from ._ellipsometry import Ellipsometric as Ellipsometric
from ._ellipsometry import Ellipsometry as Ellipsometry
from ._ellipsometry import ellipsometry as ellipsometry
from ._ellipsometry import psi_delta as psi_delta
from ._ellipsometry import reflection_amplitudes as reflection_amplitudes
from ._fresnel import fresnel_amplitudes as fresnel_amplitudes
from ._fresnel import normal_wavevector as normal_wavevector
from ._he_torrance import HeTorrance as HeTorrance
from ._he_torrance import he_torrance_brdf as he_torrance_brdf
from ._illumination import Diffuse as Diffuse
from ._illumination import Response as Response
from ._illumination import diffuse as diffuse
from ._illumination import snell_invariant as snell_invariant
from ._illumination import specular as specular
from ._geometry import BRDF as BRDF
from ._geometry import Directional as Directional
from ._geometry import Geometry as Geometry
from ._geometry import Specular as Specular
from ._geometry import Sphere as Sphere
from ._geometry import fixed_optics as fixed_optics
from ._geometry import geometry_kinds as geometry_kinds
from ._geometry import invert_background as invert_background
from ._geometry import parse_geometry as parse_geometry
from ._geometry import reflectance as reflectance
from ._materials import Cauchy as Cauchy
from ._materials import Index as Index
from ._materials import Material as Material
from ._materials import Sellmeier as Sellmeier
from ._materials import Tabulated as Tabulated
from ._optics import Optics as Optics
from ._oscillators import CauchyUrbach as CauchyUrbach
from ._oscillators import CodyLorentz as CodyLorentz
from ._oscillators import Drude as Drude
from ._oscillators import Lorentz as Lorentz
from ._oscillators import TaucLorentz as TaucLorentz
from ._oscillators import photon_energy as photon_energy
from ._programs import compilation_cache_dir as compilation_cache_dir
from ._programs import use_compilation_cache as use_compilation_cache
from ._polarimetry import apply_mueller as apply_mueller
from ._polarimetry import cloude_eigenvalues as cloude_eigenvalues
from ._polarimetry import coherency_matrix as coherency_matrix
from ._polarimetry import degree_of_polarization as degree_of_polarization
from ._polarimetry import diffuse_mueller as diffuse_mueller
from ._polarimetry import is_physical as is_physical
from ._polarimetry import mueller_from_jones as mueller_from_jones
from ._polarimetry import polarized_brdf as polarized_brdf
from ._polarimetry import specular_mueller as specular_mueller
from ._polarimetry import stokes as stokes
from ._progress import reporter as progress_reporter
from ._quadrature import DEFAULT_NODES as DEFAULT_NODES
from ._render_tables import CoatingTables as CoatingTables
from ._render_tables import coating_tables as coating_tables
from ._render_tables import interpolate_k_d as interpolate_k_d
from ._render_tables import interpolate_k_r as interpolate_k_r
from ._render_tables import interpolate_k_t as interpolate_k_t
from ._quadrature import hemispherical_rule as hemispherical_rule
from ._rough import RoughBRDF as RoughBRDF
from ._rough import microfacet_distribution as microfacet_distribution
from ._rough import rough_brdf as rough_brdf
from ._rough import smith_lambda as smith_lambda
from ._kubelka_munk import KubelkaMunk as KubelkaMunk
from ._kubelka_munk import Mixture as Mixture
from ._kubelka_munk import Paint as Paint
from ._kubelka_munk import PaintLayer as PaintLayer
from ._kubelka_munk import k_over_s as k_over_s
from ._kubelka_munk import km_r_infinity as km_r_infinity
from ._kubelka_munk import km_reflectance as km_reflectance
from ._kubelka_munk import km_transmittance as km_transmittance
from ._kubelka_munk import layered as layered
from ._leaves import Leaf as Leaf
from ._leaves import LeafRole as LeafRole
from ._leaves import file_fields as file_fields
from ._leaves import leaf as leaf
from ._leaves import leaf_role_at as leaf_role_at
from ._leaves import optics_fixed_at as optics_fixed_at
from ._leaves import replace_at as replace_at
from ._leaves import stack_leaves as stack_leaves
from ._stack import ExitMedium as ExitMedium
from ._stack import LambertianBackground as LambertianBackground
from ._stack import Layer as Layer
from ._stack import Stack as Stack
from ._stack import Substrate as Substrate
from ._stack import TabulatedSpectrum as TabulatedSpectrum
from ._stack import as_spectrum as as_spectrum
from ._stack import check_stack as check_stack
from ._validate import LayerstackError as LayerstackError
from ._validate import LayerstackWarning as LayerstackWarning
from ._validate import traced_checks_off as traced_checks_off
from .io import Measurement as Measurement
from .io import load_fit_stack as load_fit_stack
from .io import load_stack as load_stack
from .io import parse_wavelengths as parse_wavelengths
from .io import read_csv_columns as read_csv_columns
from .io import read_measurement as read_measurement
from .io import read_spectra_csv as read_spectra_csv
from .io import save_spectra_csv as save_spectra_csv
from .io import save_stack as save_stack
from .io import stack_from_dict as stack_from_dict
from .io import stack_to_dict as stack_to_dict
from .io import write_measurement_csv as write_measurement_csv

__all__ = [
    "apply_mueller",
    "as_cube",
    "as_spectrum",
    "BRDF",
    "Bruggeman",
    "Cauchy",
    "CauchyUrbach",
    "check_stack",
    "cloude_eigenvalues",
    "coated_rough",
    "CoatedRough",
    "coating_tables",
    "CoatingTables",
    "CodyLorentz",
    "coherency_matrix",
    "ColourSpace",
    "compilation_cache_dir",
    "database_version",
    "DatabaseFormula",
    "DEFAULT_NODES",
    "degree_of_polarization",
    "delta_e_2000",
    "delta_e_ab",
    "diffuse",
    "Diffuse",
    "diffuse_mueller",
    "Directional",
    "Drude",
    "Ellipsometric",
    "ellipsometry",
    "Ellipsometry",
    "ExitMedium",
    "file_fields",
    "fixed_optics",
    "fresnel_amplitudes",
    "Geometry",
    "geometry_kinds",
    "he_torrance_brdf",
    "hemispherical_rule",
    "HeTorrance",
    "Index",
    "interpolate_k_d",
    "interpolate_k_r",
    "interpolate_k_t",
    "invert_background",
    "is_physical",
    "k_over_s",
    "km_r_infinity",
    "km_reflectance",
    "km_transmittance",
    "KubelkaMunk",
    "LambertianBackground",
    "Layer",
    "layered",
    "LayerstackError",
    "LayerstackWarning",
    "Leaf",
    "leaf",
    "leaf_role_at",
    "LeafRole",
    "load_fit_stack",
    "load_stack",
    "Looyenga",
    "Lorentz",
    "material",
    "Material",
    "material_sources",
    "Measurement",
    "memory_budget",
    "MEMORY_FRACTION",
    "MemoryBudget",
    "microfacet_distribution",
    "Mixture",
    "mueller_from_jones",
    "normal_wavevector",
    "OBSERVERS",
    "open_cube",
    "Optics",
    "optics_fixed_at",
    "Paint",
    "PaintLayer",
    "parse_geometry",
    "parse_wavelengths",
    "photon_energy",
    "polarized_brdf",
    "predict",
    "progress_reporter",
    "psi_delta",
    "read_csv_columns",
    "read_envi",
    "read_measurement",
    "read_netcdf",
    "read_npy",
    "read_spectra_csv",
    "read_zarr",
    "RealLike",
    "reflectance",
    "reflection_amplitudes",
    "replace_at",
    "Response",
    "rough_brdf",
    "RoughBRDF",
    "save_spectra_csv",
    "save_stack",
    "Sellmeier",
    "smith_lambda",
    "snell_invariant",
    "Specular",
    "specular",
    "specular_mueller",
    "Sphere",
    "srgb_encode",
    "Stack",
    "stack_from_dict",
    "stack_leaves",
    "stack_to_dict",
    "stokes",
    "Substrate",
    "Tabulated",
    "TabulatedSpectrum",
    "TaucLorentz",
    "traced_checks_off",
    "use_compilation_cache",
    "VISIBLE_RANGE_NM",
    "write_measurement_csv",
    "write_zarr_cube",
    "xyz_to_lab",
    "xyz_to_xyy",
]

__version__ = "0.1.0"
