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

from ._base.memory import MEMORY_FRACTION as MEMORY_FRACTION
from ._base.memory import MemoryBudget as MemoryBudget
from ._base.memory import memory_budget as memory_budget
from ._instruments.batched import predict as predict
from ._appearance.coated_rough import CoatedRough as CoatedRough
from ._appearance.coated_rough import coated_rough as coated_rough
from ._instruments.colour import OBSERVERS as OBSERVERS
from ._instruments.colour import VISIBLE_RANGE_NM as VISIBLE_RANGE_NM
from ._instruments.colour import ColourSpace as ColourSpace
from ._instruments.colour import delta_e_2000 as delta_e_2000
from ._instruments.colour import delta_e_ab as delta_e_ab
from ._instruments.colour import srgb_encode as srgb_encode
from ._instruments.colour import xyz_to_lab as xyz_to_lab
from ._instruments.colour import xyz_to_xyy as xyz_to_xyy
from ._files.cubes import as_cube as as_cube
from ._files.cubes import open_cube as open_cube
from ._files.cubes import read_envi as read_envi
from ._files.cubes import read_netcdf as read_netcdf
from ._files.cubes import read_npy as read_npy
from ._files.cubes import read_zarr as read_zarr
from ._files.cubes import write_zarr_cube as write_zarr_cube
from ._base.custom_types import RealLike as RealLike
from ._media.database import DatabaseFormula as DatabaseFormula
from ._media.database import database_version as database_version
from ._media.database import material as material
from ._media.database import material_sources as material_sources
from ._media.effective_medium import Bruggeman as Bruggeman
from ._media.effective_medium import Looyenga as Looyenga
from ._instruments.ellipsometer import Ellipsometric as Ellipsometric
from ._instruments.ellipsometry import Ellipsometry as Ellipsometry
from ._instruments.ellipsometry import ellipsometry as ellipsometry
from ._instruments.ellipsometry import psi_delta as psi_delta
from ._instruments.ellipsometry import reflection_amplitudes as reflection_amplitudes
from ._instruments.ellipsometer import SharedReadings as SharedReadings
from ._instruments.ellipsometer import shared_readings as shared_readings
from ._kernels.fresnel import fresnel_amplitudes as fresnel_amplitudes
from ._kernels.fresnel import normal_wavevector as normal_wavevector
from ._appearance.he_torrance import HeTorrance as HeTorrance
from ._appearance.he_torrance import he_torrance_brdf as he_torrance_brdf
from ._stacks.illumination import Diffuse as Diffuse
from ._stacks.illumination import Response as Response
from ._stacks.illumination import diffuse as diffuse
from ._stacks.illumination import snell_invariant as snell_invariant
from ._stacks.illumination import specular as specular
from ._instruments.directional import BRDF as BRDF
from ._instruments.directional import Directional as Directional
from ._instruments.geometry import Geometry as Geometry
from ._instruments.geometry import OpticalGeometry as OpticalGeometry
from ._instruments.specular import Specular as Specular
from ._instruments.sphere import Sphere as Sphere
from ._instruments.geometry import fixed_optics as fixed_optics
from ._instruments.geometry import geometry_kinds as geometry_kinds
from ._instruments.geometry import invert_background as invert_background
from ._instruments.geometry import parse_geometry as parse_geometry
from ._instruments.geometry import reflectance as reflectance
from ._media.materials import Cauchy as Cauchy
from ._media.materials import Index as Index
from ._media.materials import Material as Material
from ._media.materials import Sellmeier as Sellmeier
from ._media.materials import Tabulated as Tabulated
from ._instruments.optics import Optics as Optics
from ._media.oscillators import CauchyUrbach as CauchyUrbach
from ._media.oscillators import CodyLorentz as CodyLorentz
from ._media.oscillators import Drude as Drude
from ._media.oscillators import Lorentz as Lorentz
from ._media.oscillators import TaucLorentz as TaucLorentz
from ._media.oscillators import photon_energy as photon_energy
from ._base.programs import compilation_cache_dir as compilation_cache_dir
from ._base.programs import use_compilation_cache as use_compilation_cache
from ._instruments.polarimetry import apply_mueller as apply_mueller
from ._instruments.polarimetry import cloude_eigenvalues as cloude_eigenvalues
from ._instruments.polarimetry import coherency_matrix as coherency_matrix
from ._instruments.polarimetry import degree_of_polarization as degree_of_polarization
from ._instruments.polarimetry import diffuse_mueller as diffuse_mueller
from ._instruments.polarimetry import is_physical as is_physical
from ._instruments.polarimetry import mueller_from_jones as mueller_from_jones
from ._instruments.polarimetry import polarized_brdf as polarized_brdf
from ._instruments.polarimetry import specular_mueller as specular_mueller
from ._instruments.polarimetry import stokes as stokes
from ._base.progress import reporter as progress_reporter
from ._kernels.quadrature import DEFAULT_NODES as DEFAULT_NODES
from ._appearance.render_tables import CoatingTables as CoatingTables
from ._appearance.render_tables import coating_tables as coating_tables
from ._appearance.render_tables import interpolate_k_d as interpolate_k_d
from ._appearance.render_tables import interpolate_k_r as interpolate_k_r
from ._appearance.render_tables import interpolate_k_t as interpolate_k_t
from ._kernels.quadrature import hemispherical_rule as hemispherical_rule
from ._appearance.rough import RoughBRDF as RoughBRDF
from ._appearance.rough import microfacet_distribution as microfacet_distribution
from ._appearance.rough import rough_brdf as rough_brdf
from ._appearance.rough import smith_lambda as smith_lambda
from ._stacks.kubelka_munk import KubelkaMunk as KubelkaMunk
from ._stacks.kubelka_munk import Mixture as Mixture
from ._stacks.kubelka_munk import Paint as Paint
from ._stacks.kubelka_munk import PaintLayer as PaintLayer
from ._stacks.kubelka_munk import k_over_s as k_over_s
from ._stacks.kubelka_munk import km_r_infinity as km_r_infinity
from ._stacks.kubelka_munk import km_reflectance as km_reflectance
from ._stacks.kubelka_munk import km_transmittance as km_transmittance
from ._stacks.kubelka_munk import layered as layered
from ._base.leaves import Leaf as Leaf
from ._base.leaves import LeafRole as LeafRole
from ._base.leaves import file_fields as file_fields
from ._base.leaves import leaf as leaf
from ._base.leaves import leaf_role_at as leaf_role_at
from ._base.leaves import optics_fixed_at as optics_fixed_at
from ._base.leaves import replace_at as replace_at
from ._base.leaves import stack_leaves as stack_leaves
from ._stacks.stack import ExitMedium as ExitMedium
from ._stacks.stack import LambertianBackground as LambertianBackground
from ._stacks.stack import Layer as Layer
from ._stacks.stack import Stack as Stack
from ._stacks.stack import Substrate as Substrate
from ._stacks.stack import TabulatedSpectrum as TabulatedSpectrum
from ._stacks.stack import as_spectrum as as_spectrum
from ._stacks.stack import check_stack as check_stack
from ._base.validate import LayerstackError as LayerstackError
from ._base.validate import LayerstackWarning as LayerstackWarning
from ._base.validate import traced_checks_off as traced_checks_off
from .io import Measurement as Measurement
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
    "OpticalGeometry",
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
    "shared_readings",
    "SharedReadings",
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
