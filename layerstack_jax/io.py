r"""Files: stack descriptions (TOML), spectra (CSV) and wavelength grids.

Stack files
-----------
A stack is described in a TOML file, read with :func:`load_stack` (or, from a dict already in
memory, :func:`stack_from_dict`). Layers are listed from the side the light comes from::

    description = "optional free text"

    [ambient]                 # optional; default: air, n = 1.0
    n = 1.0                   # real (light comes from here): a number or a dispersion (below)

    [[layers]]                # zero or more, top to bottom
    name = "varnish"          # optional; used in messages (default "layer 1", "layer 2" ...)
    n = 1.52                  # refractive index: number or dispersion (below)
    k = 0.0                   # optional extinction coefficient >= 0 (number)
    thickness_nm = 20000      # required, >= 0
    coherent = false          # required: true for a thin film (interference), false for a
                              # thick layer (intensities add; Beer's law)
    alpha_per_nm = 2e-5       # optional, incoherent layers only: absorption coefficient in
                              # 1/nm, a number, { table = "alpha.csv" } (columns
                              # wavelength_nm, alpha_per_nm) or inline
                              # { wavelength_nm = [...], values = [...] }

    [substrate]               # either a specular semi-infinite substrate ...
    n = 1.52                  # number or dispersion (below)
    k = 0.0                   # optional

    [background]              # ... or a Lambertian (diffusing) background: exactly one of the two
    n = 1.5                   # real index of the background's binder
    rho_g = 0.8               # intrinsic reflectance in [0, 1]: a number, { table = "rho.csv" }
                              # (columns wavelength_nm, rho_g) or inline
                              # { wavelength_nm = [...], values = [...] }

    [kubelka_munk]            # ... or a scattering body (paint, ink, paper) under its binder:
    n = 1.5                   # real index of the binder
    thickness_nm = 30000      # optional: absent = opaque (R infinity)
    ground_reflectance = 0.8  # optional diffuse reflectance under the body (number or spectrum; 0)
    K_per_nm = 1e-5           # Kubelka-Munk absorption K and scattering S in 1/nm (numbers or
    S_per_nm = 5e-4           # spectra as alpha_per_nm) ... or a Duncan mixture of pigments:
    # [[kubelka_munk.pigments]]   name = "red", K_per_nm = ..., S_per_nm = ..., concentration = 0.4
    # (exactly one exit table: [substrate], [background] or [kubelka_munk]; layerstack_jax.KubelkaMunk)

Free parameters (for ``layerstack fit``; the reader returns them as :class:`Annotation` records, read by
:func:`fitting.load_fit_file`): a layer's ``thickness_nm``, ``alpha_per_nm``, ``n`` and
``k`` (numbers), the background's ``rho_g`` and a Kubelka–Munk body's ``thickness_nm``,
``ground_reflectance`` and pigment ``concentration`` s may be written as an inline table that adds
fitting information to the value::

    thickness_nm = { value = 30000, free = true, min = 0, max = 1e5 }
    alpha_per_nm = { table = "alpha.csv", free = true, basis = 8 }   # spectrum on 8 B-splines
    rho_g = { value = 0.5, free = true, basis = "free" }              # one value per wavelength

Keys: ``value`` (or, for spectra, ``table`` / ``wavelength_nm`` + ``values``), ``free`` (bool),
``min``/``max`` (bounds; defaults thickness ≥ 0, α ≥ 0, 0 ≤ ρg ≤ 1, n ≥ 1), ``basis`` (spectra:
number of B-spline functions or ``"free"``), ``per_sample`` (``layerstack fit --joint``: one value
per spectrum), ``known`` and ``smoothness`` (penalty weight). A per-sample number may start from
one value per spectrum, some of them known (kept, not fitted) — a calibration series with one
thickness measured::

    thickness_nm = { value = [115000, 480000], free = true, per_sample = true, known = [true, false] }

:func:`load_stack` ignores these keys (the value is used; of a list, the first);
``stack_from_dict(d, annotations=[])`` also returns them, unread (:data:`ANNOTATION_KEYS`), and
:mod:`fitting` checks and interprets them. Tables of α, ρg or k whose rounding or
baseline noise dips below 0 by at most 1e-3 of the table's largest value are clipped to 0 with a
:class:`LayerstackWarning`; larger negative values are refused.

Dispersion: wherever ``n`` is accepted it may also be an inline table with exactly one of

* ``n = { cauchy = [A, B, C] }`` — :math:`n = A + B/\lambda^2 + C/\lambda^4`, λ in µm
  (1 to 3 coefficients; ``k`` from the ``k`` key, constant);
* ``n = { sellmeier = { B = [...], C = [...] } }`` — :math:`n^2 = 1 + \sum B_i\lambda^2/(\lambda^2 - C_i)`,
  λ in µm, :math:`C_i` in µm² (``k`` from the ``k`` key, constant);
* ``n = { table = "file.csv" }`` — CSV with columns ``wavelength_nm, n`` and optionally ``k``
  (if the file has no ``k`` column, the ``k`` key gives a constant k);
* ``n = { wavelength_nm = [...], n = [...], k = [...] }`` — the same table inline (k optional);
* ``n = { material = "Au", source = "Johnson" }`` — a real material from the
  refractiveindex.info database shipped offline (:func:`~layerstack_jax.material`): ``material``
  is the database's material id (or a ``"shelf/book/page"`` path), ``source`` the page id or
  words of its title (``"Johnson and Christy"``), needed when the material has several pages
  (:func:`~layerstack_jax.material_sources` lists them, with the sample's form — amorphous,
  crystalline, thin film — where the database says it: amorphous and crystalline Si share
  ``"Si"``); optional ``shelf``. n and k both come from the database (no ``k`` key); wavelengths outside
  the data's range are an error;
* ``n = { tauc_lorentz = { Eg = 3.2, A = 150, E0 = 4.2, C = 1.5, eps_inf = 2.2 } }`` — a dispersion
  model by name with its coefficients as the class's fields (units there, eV for energies):
  ``lorentz`` (:class:`~layerstack_jax.Lorentz`), ``drude`` (:class:`~layerstack_jax.Drude`),
  ``tauc_lorentz``, ``cody_lorentz``, ``cauchy_urbach``; a coefficient is a number or, for
  several oscillators, a list; n and k both come from the model (no ``k`` key);
* ``n = { bruggeman = { materials = [{ material = "Si", source = "Aspnes" }, 1.0], fractions = 0.5 } }``
  — an effective medium (:class:`~layerstack_jax.Bruggeman`, or ``looyenga``:
  :class:`~layerstack_jax.Looyenga`) of two or more ``materials``, each written as ``n`` is (a
  number, any of the dispersions above) or as ``{ n = ..., k = ... }``; ``fractions`` are the
  volume fractions of the first m − 1 materials, each in [0, 1] (a number for two materials, else
  a list; the last material fills the rest). The line above is surface roughness on silicon: a
  50 % void layer. n and k come from the mixture (no ``k`` key).

In ``[[layers]]``, any coefficient of a model, the Cauchy coefficients, the Sellmeier terms, an
effective medium's fractions and its materials' coefficients can be declared free like a
thickness: ``A = { value = 150, free = true, min = 10, max = 500 }``, ``cauchy = [{ value = 1.46,
free = true, min = 1.3, max = 1.7 }, 0.004]``, ``sellmeier = { B = [{ value = 0.7, free = true,
min = 0.5, max = 0.9 }, 0.41, 0.90], C = [0.0047, 0.0135, 97.9] }``, ``fractions = { value = 0.5,
free = true }``. They are fitted as ``tauc_lorentz.A[film]``, ``cauchy.A[film]``; an entry of a
list by its 1-based position, ``sellmeier.B1[glass]``, ``lorentz.A2[film]``,
``looyenga.fractions2[mix]``; a material of a mixture by its position,
``bruggeman.materials1.cauchy.A[rough]``. Bounds: give them, except for fractions (default and
limit [0, 1]); a fraction list's sum ≤ 1 is not a bound, keep the start well inside.

The instrument
--------------
An optional ``[instrument]`` table sets fields of the measurement geometries that
``layerstack fit`` and ``layerstack predict`` use with the stack (the geometry of a fit comes
from the instrument file or ``-g``; these are its non-idealities), in the field's unit, each a
number or a free-parameter table::

    [instrument]
    angle_offset_deg = { value = 0.0, free = true, min = -1.0, max = 1.0 }   # one for all angles
    bandwidth_nm = 2.0                                                       # monochromator FWHM
    thickness_spread = { value = 0.01, free = true, min = 0.0, max = 0.1 }
    nonuniform_layer = "film"          # the layer whose thickness spreads (name or 0-based position)

Any numeric field of the geometry is accepted — an ellipsometer's (:class:`~layerstack_jax.Ellipsometric`)
``angle_offset_deg``, ``bandwidth_nm``, ``thickness_spread``; a spectrophotometer's fields
(:class:`~layerstack_jax.Sphere`, :class:`~layerstack_jax.Directional`) such as its port cone or
apertures — and a key that is not a field of the geometry is an error naming it and the
geometry's fields. A free key is fitted as one value shared by every dataset of the fit whose
geometry has the field (``fitting.instrument(key, "all")``), named by the key
(``angle_offset_deg``). :func:`load_instrument` reads the table into :class:`InstrumentSettings`;
:func:`instrument_geometry` applies it to a geometry (``layerstack predict`` applies it to every
geometry asked for, each taking the keys it has, and refuses a key that none of them has).

Tables are linearly interpolated and never extrapolated: predicting outside a table's range is
an error. Relative file names are taken relative to the directory of the TOML file.

CSV files need a header row naming the columns (any order, case-insensitive); lines starting
with ``#`` before the header and blank lines are ignored; wavelengths must increase strictly.

Every problem in a file (missing or unknown key — unknown keys are rejected to catch typos —,
both or neither of ``[substrate]`` and ``[background]``, a negative number, a malformed CSV …)
raises :class:`~layerstack_jax.LayerstackError` with a message naming the file, the table and
key, and what is wrong.

Writing: :func:`save_stack` writes a :class:`Stack` (via :func:`stack_to_dict`) or a stack dict as
a TOML stack file, with optional ``#`` header lines.

Files built on the stack file
-----------------------------
Design files (``layerstack design``) add ``[[targets]]``, ``[optimizer]`` and ``[robustness]``
tables to a stack file; their format belongs to :mod:`fitting` (see ``fitting._design_file``),
which reads them with the same grammar (:class:`FileLocation`, :func:`reject_unknown_keys`,
:func:`read_number`, :func:`read_material`, :data:`ANNOTATION_KEYS`, :func:`stack_from_dict`), so
every message has the same form.

Measurement files
-----------------
:func:`read_measurement` reads what instruments export and returns one :class:`Measurement`
(quantity, angles in degrees, wavelengths in nm, values, σ where the file has them, the file's
conventions): Woollam WVASE / CompleteEASE ``.dat`` (:func:`read_woollam`), Sentech SpectraRay
``.txt`` (:func:`read_sentech`), Accurion EP3/EP4 (:func:`read_accurion`), NeXus NXellipsometry
(:func:`read_nexus`, needs ``h5py``), JCAMP-DX R/T spectra (:func:`read_jcamp`, needs ``jcamp``)
and plain CSV with units in the header (:func:`read_measurement_csv`); the format is sniffed from
the content (:func:`sniff_format`). ψ, Δ and Mueller elements are kept as the instrument reports
them — the library's public convention is the instruments' — and only units are converted at
the door. A file that cannot be read raises :class:`LayerstackError` naming the line and why.
Real files with their provenance and licences: ``examples/data/README.md``.

Spectra and wavelengths
-----------------------
:func:`save_spectra_csv` writes ``wavelength_nm`` and named columns; :func:`parse_wavelengths`
turns ``"380:780:5"`` (start:stop:step in nm, stop included when on the grid), ``"550"`` or
``"450,550,650"`` into an array.
"""

from __future__ import annotations

from ._files.annotations import ANNOTATION_KEYS as ANNOTATION_KEYS
from ._files.annotations import Annotation as Annotation
from ._files.file_grammar import FileLocation as FileLocation
from ._files.file_grammar import check_grid as check_grid
from ._files.file_grammar import check_range as check_range
from ._files.file_grammar import is_number as is_number
from ._files.file_grammar import named_tables as named_tables
from ._files.file_grammar import read_number as read_number
from ._files.file_grammar import read_number_list as read_number_list
from ._files.file_grammar import read_toml as read_toml
from ._files.file_grammar import reject_unknown_keys as reject_unknown_keys
from ._files.instrument_file import InstrumentSettings as InstrumentSettings
from ._files.instrument_file import check_instrument_used as check_instrument_used
from ._files.instrument_file import instrument_geometry as instrument_geometry
from ._files.instrument_file import instrument_settings as instrument_settings
from ._files.instrument_file import load_instrument as load_instrument
from ._files.material_file import read_material as read_material
from ._files.measurement import Measurement as Measurement
from ._files.readers import read_accurion as read_accurion
from ._files.readers import read_jcamp as read_jcamp
from ._files.readers import read_measurement as read_measurement
from ._files.readers import read_measurement_csv as read_measurement_csv
from ._files.readers import read_nexus as read_nexus
from ._files.readers import read_sentech as read_sentech
from ._files.readers import read_woollam as read_woollam
from ._files.readers import sniff_format as sniff_format
from ._files.readers import wavelength_to_nm as wavelength_to_nm
from ._files.readers import write_measurement_csv as write_measurement_csv
from ._files.spectra_csv import is_spectra_csv as is_spectra_csv
from ._files.spectra_csv import parse_values as parse_values
from ._files.spectra_csv import parse_wavelengths as parse_wavelengths
from ._files.spectra_csv import read_csv_columns as read_csv_columns
from ._files.spectra_csv import read_spectra_csv as read_spectra_csv
from ._files.spectra_csv import save_spectra_csv as save_spectra_csv
from ._files.stack_file import load_stack as load_stack
from ._files.stack_file import stack_from_dict as stack_from_dict
from ._files.stack_writer import save_stack as save_stack
from ._files.stack_writer import stack_to_dict as stack_to_dict

__all__ = [
    "load_stack",
    "stack_from_dict",
    "stack_to_dict",
    "save_stack",
    "Annotation",
    "InstrumentSettings",
    "instrument_settings",
    "load_instrument",
    "instrument_geometry",
    "check_instrument_used",
    "read_csv_columns",
    "read_spectra_csv",
    "is_spectra_csv",
    "save_spectra_csv",
    "parse_values",
    "parse_wavelengths",
    "ANNOTATION_KEYS",
    "FileLocation",
    "named_tables",
    "reject_unknown_keys",
    "is_number",
    "read_number",
    "read_number_list",
    "check_grid",
    "check_range",
    "read_toml",
    "read_material",
    "Measurement",
    "read_measurement",
    "read_woollam",
    "read_sentech",
    "read_accurion",
    "read_nexus",
    "read_jcamp",
    "read_measurement_csv",
    "write_measurement_csv",
    "sniff_format",
    "wavelength_to_nm",
]
