r"""The residual function of a fit.

A :class:`~fitting.Dataset` (:mod:`fitting._dataset`) is what one instrument geometry read on
every sample of the fit. An :class:`Objective` joins a template :class:`~layerstack_jax.Stack`, the model grid,
the free :class:`~fitting.Parameter` s (numbers of the stack, or of a dataset's geometry:
:func:`~fitting.instrument`) and one or several datasets (several geometries, R and T,
CIELAB colours of a colorimeter through a :class:`layerstack_jax.ColourSpace`, the bare background).

Residuals (model − data, weighted): for each dataset,
:math:`r = m\,w\,(f(\lambda; x) \ominus y)` with :math:`w = 1/\sigma` (or the given weights, default 1)
and :math:`m \in \{0, 1\}` the mask, where :math:`f \ominus y` is the geometry's own
:meth:`~layerstack_jax.Geometry.residual` — the difference :math:`f - y`, or for an
ellipsometer's Δ the difference wrapped into (−180°, 180°] (a Δ crossing ±180° is compared on
the circle; CIELAB datasets use the plain difference), flattened and concatenated over datasets, followed by the
smoothness penalties :math:`\sqrt{\mu}\,\Delta^2 (B c)` of spectral parameters. The model
:math:`f` is the public forward function :func:`layerstack_jax.reflectance` applied to the
template stack with the parameters put in by ``equinox.tree_at`` — one stack per sample, vmapped.

The data, σ and mask travel as a pytree argument (:meth:`Objective.args`) of the pure residual
function (:meth:`Objective.residuals`), so a second fit of the same objective with other data
reuses the compiled solver.
"""

from __future__ import annotations

import dataclasses
from typing import Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax import (
    DEFAULT_NODES,
    Geometry,
    LayerstackError,
    Stack,
    TabulatedSpectrum,
    file_fields,
    fixed_optics,
    optics_fixed_at,
    reflectance,
    shared_readings,
)

from ._dataset import Dataset, _prepare
from ._layout import Layout, resolve_parameter
from ._parameters import Parameter, is_instrument_path

__all__ = ["Objective"]


def _measure(stack: Stack, grid, g: Geometry, nodes: int, optics=None, colour=None):
    """What the instrument of geometry ``g`` reads (:func:`layerstack_jax.reflectance`, reusing ``optics``, a :class:`layerstack_jax.Optics`, if given),
    converted to CIELAB by ``colour`` (a :class:`layerstack_jax.ColourSpace`) if given."""
    spectrum = reflectance(stack, grid, g, nodes=nodes, optics=optics)
    return spectrum if colour is None else colour.Lab(spectrum)


def _leaves_optics_fixed(stack: Stack, path: tuple) -> bool:
    """True if a free leaf at ``path`` leaves the :class:`layerstack_jax.Optics` unchanged, as its
    field declares (:func:`layerstack_jax.optics_fixed_at`: a thick layer's thickness or α, ρg …);
    an instrument's number (a path into the datasets' geometries) changes the optics."""
    return not is_instrument_path(path) and optics_fixed_at(stack, path)


def _has_range(x) -> bool:
    """A material or spectrum known only over a wavelength range (a table, a database formula)."""
    return isinstance(x, TabulatedSpectrum) or hasattr(type(x), "data_range_nm")


def _data_range(x) -> tuple:
    if isinstance(x, TabulatedSpectrum):
        return float(x.wavelength_nm[0]), float(x.wavelength_nm[-1])
    return x.data_range_nm


def _where(stack: Stack, path) -> str:
    """``layers[1] (TiO2): index`` … for a key path into ``stack``."""
    keys = [getattr(k, "name", getattr(k, "idx", getattr(k, "key", k))) for k in path]
    if len(keys) >= 2 and keys[0] == "layers" and isinstance(keys[1], int):
        layer = stack.layers[keys[1]]
        rest = ".".join(str(k) for k in keys[2:]) or "index"
        return f"layers[{keys[1]}] ({layer.name or 'unnamed'}): {rest}"
    if keys[:1] == ["exit"] and len(keys) >= 2 and keys[1] != "index":  # a number of the exit: its file key
        key = {f: k for k, f in file_fields(stack.exit).items()}.get(keys[1], ".".join(str(k) for k in keys[1:]))
        return f"{stack.exit.label} {key}"
    return (" ".join(str(k) for k in keys[:1]) + " " + ".".join(str(k) for k in keys[1:])).strip()


def check_table_ranges(stack: Stack, grid) -> None:
    """Raise :class:`LayerstackError` when a model wavelength ``grid`` (nm, ``(wl,)``) lies
    outside the range of a tabulated material, database formula or tabulated spectrum of
    ``stack``, naming the layer (or medium), the material and both ranges. Run once when an
    :class:`Objective` is built: inside a compiled solve the same error surfaces only as an
    opaque runtime callback failure."""
    g = np.asarray(grid, dtype=float)
    leaves, _ = jax.tree_util.tree_flatten_with_path(stack, is_leaf=_has_range)
    for path, leaf in leaves:
        if not _has_range(leaf):
            continue
        lo, hi = _data_range(leaf)
        out = (g < lo - 1e-9) | (g > hi + 1e-9)
        if np.any(out):
            raise LayerstackError(
                f"{_where(stack, path)}: material {getattr(leaf, 'name', type(leaf).__name__)!r} has data for "
                f"{lo:g}–{hi:g} nm only, but the model grid spans {g.min():g}–{g.max():g} nm ({int(out.sum())} of "
                f"{g.size} model wavelengths outside, e.g. {g[out][0]:g} nm): narrow the model grid or choose a "
                "material source that covers it (nothing is extrapolated)"
            )


def _bare(stack: Stack) -> Stack:
    """The stack with its layers removed: what a bare-background :class:`~fitting.Dataset` measures."""
    return Stack(stack.ambient, [], stack.exit)


class Objective:
    """Model + data + free parameters: the residual function of a fit (module docstring).

    Args:
        stack: template stack (structure and fixed values; free leaves give the starting values).
        wavelength_nm: model grid in nm, ``(wl,)``.
        datasets: one :class:`~fitting.Dataset` or a sequence (joint fit over geometries / quantities).
        parameters: the free :class:`Parameter` s (constructors :func:`~fitting.thickness`,
            :func:`~fitting.alpha`, :func:`~fitting.rho_g` …).
        n_samples: number of samples (rows of every dataset); default from the first dataset.
        nodes: quadrature nodes per segment of the diffuse integrals.
    """

    def __init__(self, stack: Stack, wavelength_nm, datasets, parameters: Sequence[Parameter], *,
                 n_samples: Optional[int] = None, nodes: int = DEFAULT_NODES):
        if not isinstance(stack, Stack):
            raise LayerstackError(f"stack must be a layerstack_jax.Stack, got {type(stack).__name__}")
        grid = np.asarray(wavelength_nm, dtype=float)
        if grid.ndim != 1 or grid.size < 1 or np.any(~np.isfinite(grid)) or np.any(grid <= 0):
            raise LayerstackError("wavelength_nm: the model grid must be a 1-D array of finite wavelengths > 0 nm")
        if grid.size > 1 and np.any(np.diff(grid) <= 0):
            raise LayerstackError("wavelength_nm: the model grid must increase strictly")
        if isinstance(datasets, Dataset):
            datasets = [datasets]
        datasets = list(datasets)
        if not datasets:
            raise LayerstackError("an objective needs at least one Dataset")
        for p in parameters:
            if not isinstance(p, Parameter):
                raise LayerstackError(f"parameters must be fitting.Parameter objects, got {p!r}")
        if n_samples is None:
            d0 = np.asarray(next((ds for ds in datasets if not ds.bare), datasets[0]).data)
            n_samples = 1 if d0.ndim == 1 else d0.shape[0]
        check_table_ranges(stack, grid)  # here, not as an opaque runtime error inside the solve
        prepared = [_prepare(ds, grid, n_samples, i) for i, ds in enumerate(datasets)]
        self.stack = stack
        self.wavelength = grid
        self.datasets = tuple(datasets)
        self.n_samples = int(n_samples)
        self.nodes = int(nodes)
        self.layout = Layout([resolve_parameter(p, stack, grid, self.n_samples, datasets) for p in parameters],
                             self.n_samples)
        self._data = tuple(jnp.asarray(y) for y, _, _ in prepared)
        self._weight = tuple(jnp.asarray(w) for _, w, _ in prepared)
        self._mask = tuple(np.asarray(m) for _, _, m in prepared)
        self.sigma_given = all(ds.sigma is not None for ds in datasets)
        self.n_points = int(sum(m.sum() for m in self._mask))
        self._check_wavelengths_read()
        self.optics = self._fixed_optics()
        #: what this process compiled or precomputed for this objective (solvers, lookup tables,
        #: the Jacobian's structure), filled by the fitting functions; never pickled
        self.cache: dict = {}
        # check once, eagerly, that the forward model runs on the grid (tables cover it, …)
        try:  # traced once, not run: static checks (tables cover the grid, shapes) happen at trace time
            jax.eval_shape(self.predict, jnp.asarray(self.layout.x0))
        except LayerstackError as e:
            raise LayerstackError(f"model at the starting values: {e}") from None

    def __getstate__(self) -> dict:
        """Pickled (e.g. scattered to Dask workers by :func:`~fitting.fit_cube`) without what has
        been compiled for it in this process (:attr:`cache`: solvers, lookup tables, neither
        picklable nor valid in another process); the receiving process compiles its own once."""
        state = dict(self.__dict__)
        state.pop("cache", None)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.cache = {}

    def _check_wavelengths_read(self) -> None:
        """Material tables against the wavelengths each instrument reads beyond the model grid
        (:meth:`~layerstack_jax.Geometry.wavelengths_read`: an ellipsometer's bandwidth), its
        free instrument parameters at their upper bounds where finite (the widest band a fit may
        reach), else at their starting values."""
        layout = self.layout
        x = np.where(np.isfinite(layout.upper), layout.upper, layout.x0.reshape(-1))
        geometries = layout.inject_geometries([ds.geometry for ds in self.datasets], layout.split(jnp.asarray(x)))
        for ds, g in zip(self.datasets, geometries):
            span = np.asarray(g.wavelengths_read(self.wavelength))
            if span.size and (span.min() < self.wavelength.min() or span.max() > self.wavelength.max()):
                try:
                    check_table_ranges(self.stack, span)
                except LayerstackError as e:
                    raise LayerstackError(f"dataset {ds.label}: the instrument reads {span.min():g}–{span.max():g} nm "
                                          f"(its bandwidth around the model grid): {e}") from None

    def _fixed_optics(self):
        """Per dataset, the :func:`layerstack_jax.fixed_optics` of the template stack when no
        free parameter changes it (only thick-layer thicknesses, α, ρg are free), else None.
        Computed once, eagerly, so the critical angles are known and empty quadrature segments
        are dropped; the solvers then redo only Beer's law and the adding rule at each step."""
        if not all(_leaves_optics_fixed(self.stack, p.path) for p in self.layout.params):
            return None
        out = []
        for ds in self.datasets:
            try:
                stack = _bare(self.stack) if ds.bare else self.stack
                out.append(fixed_optics(stack, self.wavelength, ds.geometry, nodes=self.nodes))  # None: no optics
            except LayerstackError as e:
                raise LayerstackError(f"dataset {ds.label}: {e}") from None
        return tuple(out)

    # ----------------------------------------------------------------- data
    @property
    def mask(self) -> tuple:
        """Per dataset, the used points: boolean ``(samples, wl)`` on the model grid."""
        return self._mask

    def args(self, data=None):
        """The data pytree passed to :meth:`residuals`: ``(data, weight)`` per dataset.

        ``data``: optional replacement spectra, a sequence (one ``(samples, wl)`` array per
        dataset) — checked like the originals, with the same σ/weights and mask.
        """
        if data is None:
            return (self._data, self._weight)
        if not isinstance(data, (list, tuple)) or len(data) != len(self.datasets):
            raise LayerstackError(f"data: give one array per dataset ({len(self.datasets)})")
        ys = []
        for i, (ds, y) in enumerate(zip(self.datasets, data)):
            mask = None if ds.colour is not None else self._mask[i] if ds.wavelength_nm is None else ds.mask
            new = dataclasses.replace(ds, data=y, mask=mask)
            ys.append(jnp.asarray(_prepare(new, self.wavelength, self.samples_of(i), i)[0]))
        return (tuple(ys), self._weight)

    def batch_args(self, data):
        """Args for many independent fits: ``data`` is one array per dataset shaped
        ``(N, samples, wl)`` (or ``(N, wl)`` for one sample); checked in bulk like
        :meth:`args`. Returns ``(data, weight)`` with a leading axis N on every array.

        An array may be a :class:`numpy.ma.MaskedArray`: its masked points are left out of
        that fit only (not checked, weight 0), on top of the dataset's own mask — a per-fit
        band mask (:func:`~fitting.fit_cube` drops a pixel's bad bands so)."""
        if not isinstance(data, (list, tuple)):
            data = [data]
        if len(data) != len(self.datasets):
            raise LayerstackError(f"data: give one array per dataset ({len(self.datasets)})")
        ys, ws, n = [], [], None
        for i, (ds, y) in enumerate(zip(self.datasets, data)):
            dropped = np.ma.getmaskarray(y) if np.ma.isMaskedArray(y) else None
            y = np.asarray(np.ma.getdata(y), dtype=float)
            k = self.samples_of(i)
            if y.ndim == 2 and k == 1:
                y = y[:, None, :]
                dropped = None if dropped is None else dropped[:, None, :]
            if y.ndim != 3 or y.shape[1] != k:
                raise LayerstackError(
                    f"dataset {i} ({ds.label}): batch data must be shaped (N, {k}, wl), got {y.shape}"
                )
            if n is None:
                n = y.shape[0]
            elif y.shape[0] != n:
                raise LayerstackError(f"dataset {i} ({ds.label}): {y.shape[0]} fits, dataset 0 has {n}")
            mask = None if ds.colour is not None else self._mask[i] if ds.wavelength_nm is None else ds.mask
            mask_n = None if mask is None else np.broadcast_to(np.asarray(mask), y.shape[1:])
            mask_all = None if mask_n is None else np.tile(mask_n, (n, 1))
            if dropped is not None:
                keep = ~dropped.reshape(-1, y.shape[-1])
                mask_all = keep if mask_all is None else mask_all & keep
            flat = dataclasses.replace(
                ds, data=y.reshape(-1, y.shape[-1]), mask=mask_all,
                sigma=None if ds.sigma is None or np.ndim(ds.sigma) < 2 else np.tile(np.asarray(ds.sigma, float), (n, 1)),
                weights=None if ds.weights is None or np.ndim(ds.weights) < 2
                else np.tile(np.asarray(ds.weights, float), (n, 1)),
            )
            if ds.sigma is not None and np.ndim(ds.sigma) < 2:
                flat = dataclasses.replace(flat, sigma=ds.sigma)
            if ds.weights is not None and np.ndim(ds.weights) < 2:
                flat = dataclasses.replace(flat, weights=ds.weights)
            yy, _, used = _prepare(flat, self.wavelength, None, i)
            ys.append(jnp.asarray(yy.reshape(n, k, -1)))
            w = jnp.broadcast_to(self._weight[i], (n,) + self._weight[i].shape)
            ws.append(w if dropped is None else jnp.where(jnp.asarray(used.reshape(w.shape)), w, 0.0))
        return (tuple(ys), tuple(ws)), n

    def samples_of(self, i: int) -> int:
        """Rows of dataset ``i``: the number of samples, or 1 for a bare-background dataset."""
        return 1 if self.datasets[i].bare else self.n_samples

    def stack_for(self, x, sample: int = 0) -> Stack:
        """The template stack with the parameters ``x`` put in, for ``sample``."""
        return self.layout.inject(self.stack, self.layout.split(jnp.asarray(x)), sample)

    def predict(self, x, optics=None) -> tuple:
        """Model spectra for physical parameters ``x``: one ``(samples, wl)`` array per dataset.

        ``optics``: :attr:`optics` (the solvers pass it as an argument of their compiled
        functions rather than as a constant); None recomputes everything."""
        coefficients = self.layout.split(x)
        per = [p.per_sample for p in self.layout.params]
        shared = [None if ps else c for c, ps in zip(coefficients, per)]
        own = [c if ps else None for c, ps in zip(coefficients, per)]
        grid = self.wavelength
        nodes = self.nodes
        optics = optics or (None,) * len(self.datasets)
        coated = [i for i, ds in enumerate(self.datasets) if not ds.bare]
        # instrument parameters (fitting.instrument) are shared scalars: put into the geometries once
        geometries = self.layout.inject_geometries([ds.geometry for ds in self.datasets], coefficients)

        # readings of one ellipsometer at several angles: computed together (one copy of the model)
        together = shared_readings([None if self.datasets[i].colour is not None or i not in coated else g
                                    for i, g in enumerate(geometries)], self.stack)

        def one(own_s):
            cs = [o if ps else s for s, o, ps in zip(shared, own_s, per)]
            st = self.layout.inject(self.stack, cs, None)
            read_together = together.read(st, grid)

            def read(i):
                if i in read_together:
                    return read_together[i]
                return _measure(st, grid, geometries[i], nodes, optics[i], self.datasets[i].colour)

            return tuple(read(i) for i in coated)

        if any(per):
            out = jax.vmap(one)(own)
        else:
            single = one(own)
            out = tuple(jnp.broadcast_to(v, (self.n_samples,) + v.shape[-1:]) for v in single)
        result = dict(zip(coated, (jnp.reshape(v, (self.n_samples, -1)) for v in out)))
        bare = [i for i, ds in enumerate(self.datasets) if ds.bare]
        if bare:
            # per-sample parameters live in the removed layers: any sample's values will do
            first = [jnp.reshape(c, (self.n_samples, -1))[0] if ps else None for c, ps in zip(coefficients, per)]
            cs = [f if ps else s for s, f, ps in zip(shared, first, per)]
            st = _bare(self.layout.inject(self.stack, cs, None))
            for i in bare:
                result[i] = jnp.reshape(_measure(st, grid, geometries[i], nodes, optics[i],
                                                 self.datasets[i].colour), (1, -1))
        return tuple(result[i] for i in range(len(self.datasets)))

    def penalty(self, x):
        """Smoothness residuals :math:`\\sqrt{\\mu}\\,\\Delta^2 (B c)` of spectral parameters."""
        out = []
        for p, c in zip(self.layout.params, self.layout.split(x)):
            mu = p.parameter.smoothness
            if mu > 0 and p.basis is not None and p.basis.shape[0] > 2:
                v = c @ jnp.asarray(p.basis).T
                out.append((jnp.sqrt(mu) * (v[..., 2:] - 2 * v[..., 1:-1] + v[..., :-2])).ravel())
        return jnp.concatenate(out) if out else jnp.zeros((0,), dtype=x.dtype)

    def weighted_residuals(self, x, args, optics=None, *, model=None):
        """Data residuals ``w · residual(f, y)`` per dataset, ``(samples, wl)`` each (0 at masked
        points), with ``residual`` the dataset geometry's :meth:`~layerstack_jax.Geometry.residual`
        (``f − y``; wrapped into (−180°, 180°] for an ellipsometer's Δ) — the one place data
        residuals are made (the solvers and the statistics call it).
        ``model``: :meth:`predict` of ``x`` when the caller already has it."""
        data, weight = args
        model = self.predict(x, optics) if model is None else model
        return tuple(w * self.residual_of(i, f, y) for i, (f, y, w) in enumerate(zip(model, data, weight)))

    def residual_of(self, i: int, model, data):
        """Unweighted residual of dataset ``i``: the geometry's
        :meth:`~layerstack_jax.Geometry.residual` of ``model`` and ``data`` (``model − data``; Δ
        wrapped for an ellipsometer), or the plain difference for a colour dataset; any shapes
        that broadcast."""
        ds = self.datasets[i]
        return model - data if ds.colour is not None else ds.geometry.residual(model, data)

    def residuals(self, x, args, optics=None):
        """Flat residual vector: weighted data residuals, then smoothness penalties."""
        parts = [r.ravel() for r in self.weighted_residuals(x, args, optics)]
        return jnp.concatenate(parts + [self.penalty(x)])

    @property
    def n_parameters(self) -> int:
        return self.layout.size
