"""Inverse problems on top of :mod:`layerstack_jax`: coating parameters from measured spectra.

Layout after refnx (Parameter → Objective → fitter → results) and optimistix:

* :mod:`fitting._parameters` — :class:`Parameter` (free leaves of a stack, bounds, spectral
  bases, shared or per sample) and the constructors :func:`thickness`, :func:`alpha`,
  :func:`rho_g`, :func:`index_n`, :func:`dispersion`; :func:`bspline_basis`;
* :mod:`fitting._dataset` — :class:`Dataset` (spectra of one geometry, σ, mask), checked and
  resampled onto the model grid; :mod:`fitting._objective` — :class:`Objective` (weighted
  residuals model − data);
* :mod:`fitting._solve` — :func:`fit` (optimistix Levenberg–Marquardt by default; Gauss–Newton,
  Dogleg, BFGS; jaxopt L-BFGS-B with exact bounds; multi-start), built from
  :mod:`fitting._solver_options` (methods, :class:`~fitting._solver_options.SolverOptions`),
  :mod:`fitting._compiled_fit` (the compiled fit of an objective; its pure parts in
  :mod:`fitting._fit_functions`, its jit in :mod:`fitting._fit_jit`, the host method in
  :mod:`fitting._host_fit`, its output record in :mod:`fitting._fit_output`),
  :mod:`fitting._bound_settling` (fits ended on a bound) and :mod:`fitting._multistart`;
* :mod:`fitting._statistics` — the one computation of χ², covariance, standard errors,
  correlations and identifiability, used by every fit; :mod:`fitting._bounded` — the one
  L-BFGS-B driver shared by fit and design; :mod:`fitting._status` — result codes and messages;
* :mod:`fitting._results` — :class:`FitResult` (values, standard errors, covariance,
  identifiability, report, JSON, plot);
* :mod:`fitting._batch` — :func:`fit_batch` (many independent fits in one compiled, chunked,
  vmapped solve) and :func:`calibration_series` (joint fit of samples sharing α(λ), ρg(λ));
* :mod:`fitting._drawdown` — :func:`drawdown_calibration`: a paint's Kubelka–Munk K(λ), S(λ)
  from drawdowns over grounds of known reflectance;
* :mod:`fitting._varnish_removal` — :func:`varnish_removal`: a fitted painting (one fit, a
  batch, a cube's maps) predicted without its varnish or under a fresh one, spectra and sRGB;
* :mod:`fitting._cube` — :func:`fit_cube`: every pixel of a hyperspectral cube, out of core,
  resumable, on Dask (local or a cluster), maps written to zarr; its regions sized in
  :mod:`fitting._cube_regions`, its zarr store and resume markers in :mod:`fitting._cube_store`;
* :mod:`fitting._design` — coating design: :func:`optimize_thicknesses` to
  :class:`SpectralTarget` / :class:`ColourTarget` (:mod:`fitting._design_targets`, with their
  :func:`merit`), thickness-error yield and robust design (:func:`thickness_yield`,
  :class:`RobustSpec`); the needle method (:func:`needle_design`) in :mod:`fitting._needle`;
* :mod:`fitting._design_file` — design files for ``layerstack design`` (targets, optimizer and
  robustness tables on top of a stack file; this module owns their format): :func:`load_design`;
  :mod:`fitting._design_run` runs one: :func:`run_design`, :func:`design_report`,
  :func:`plot_design`;
* :mod:`fitting._fit_file` — the fitting words of stack files (``free``, ``min``, ``max`` …):
  :func:`parameters_from_annotations`, :func:`load_fit_file`.

The fitting words of a stack file (``{ value = ..., free = true, min = ... }``) are read in one
place, :mod:`fitting._fit_file`: the stack file's reader returns them unread and
:func:`parameters_from_annotations` checks them and makes :class:`Parameter` objects
(:func:`load_fit_file` reads the file once for a fit).

The forward model is always the public :func:`layerstack_jax.reflectance`; fitting never reaches
inside it. Units: nm, 1/nm, degrees in geometries, as in :mod:`layerstack_jax`.
"""

from ._batch import BatchResult as BatchResult
from ._batch import background_rho_g as background_rho_g
from ._batch import calibration_series as calibration_series
from ._batch import fit_batch as fit_batch
from ._cube import CUBE_STATUS as CUBE_STATUS
from ._cube import FIT_MADE as FIT_MADE
from ._cube import NEGATIVE_SIGMAS as NEGATIVE_SIGMAS
from ._cube import fit_cube as fit_cube
from ._cube_regions import cube_regions as cube_regions
from ._cube_store import cube_parameters as cube_parameters
from ._dataset import Dataset as Dataset
from ._dataset import resample as resample
from ._design import DesignResult as DesignResult
from ._design import RobustSpec as RobustSpec
from ._design import YieldResult as YieldResult
from ._design import optimize_thicknesses as optimize_thicknesses
from ._design import thickness_yield as thickness_yield
from ._design import with_thicknesses as with_thicknesses
from ._design_file import DesignFile as DesignFile
from ._design_file import load_design as load_design
from ._design_run import DesignOutcome as DesignOutcome
from ._design_run import design_report as design_report
from ._design_run import design_stack_dict as design_stack_dict
from ._design_run import plot_design as plot_design
from ._design_run import run_design as run_design
from ._design_targets import ColourTarget as ColourTarget
from ._design_targets import SpectralTarget as SpectralTarget
from ._design_targets import merit as merit
from ._drawdown import drawdown_calibration as drawdown_calibration
from ._fit_file import FitFile as FitFile
from ._fit_file import load_fit_file as load_fit_file
from ._fit_file import load_fit_parameters as load_fit_parameters
from ._fit_file import parameter_of as parameter_of
from ._fit_file import parameters_from_annotations as parameters_from_annotations
from ._needle import NeedleScan as NeedleScan
from ._needle import insert_needle as insert_needle
from ._needle import needle_design as needle_design
from ._needle import needle_function as needle_function
from ._objective import Objective as Objective
from ._parameters import Parameter as Parameter
from ._parameters import alpha as alpha
from ._parameters import bspline_basis as bspline_basis
from ._parameters import dispersion as dispersion
from ._parameters import index_n as index_n
from ._parameters import instrument as instrument
from ._parameters import rho_g as rho_g
from ._parameters import thickness as thickness
from ._results import FitResult as FitResult
from ._solve import fit as fit
from ._solver_options import HOST_METHODS as HOST_METHODS
from ._solver_options import METHODS as METHODS
from ._varnish_removal import VarnishRemoval as VarnishRemoval
from ._varnish_removal import varnish_removal as varnish_removal

__all__ = [
    "BatchResult",
    "background_rho_g",
    "calibration_series",
    "drawdown_calibration",
    "cube_parameters",
    "varnish_removal",
    "VarnishRemoval",
    "fit_batch",
    "fit_cube",
    "cube_regions",
    "CUBE_STATUS",
    "FIT_MADE",
    "NEGATIVE_SIGMAS",
    "Dataset",
    "Objective",
    "resample",
    "Parameter",
    "alpha",
    "bspline_basis",
    "dispersion",
    "index_n",
    "instrument",
    "rho_g",
    "thickness",
    "FitResult",
    "METHODS",
    "HOST_METHODS",
    "fit",
    "ColourTarget",
    "DesignResult",
    "NeedleScan",
    "RobustSpec",
    "SpectralTarget",
    "YieldResult",
    "insert_needle",
    "merit",
    "needle_design",
    "needle_function",
    "optimize_thicknesses",
    "thickness_yield",
    "with_thicknesses",
    "DesignFile",
    "DesignOutcome",
    "design_report",
    "design_stack_dict",
    "load_design",
    "plot_design",
    "run_design",
    "load_fit_file",
    "FitFile",
    "load_fit_parameters",
    "parameters_from_annotations",
    "parameter_of",
]
