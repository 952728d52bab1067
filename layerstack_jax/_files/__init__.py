"""Files: the grammar shared by the TOML inputs (file_grammar), stack files (stack_file reads them, with
material_file, instrument_file and annotations; stack_writer writes them), spectra as CSV
(spectra_csv), measurement objects (measurement) and the readers of instrument files, one module per format
(readers), hyperspectral cubes (cubes).

Imports _base, _media and _stacks; never _instruments or _appearance.
"""
