"""The survey server, in wings that import only downwards: store -> survey -> analysis -> web -> cli, over the
modules it shares with the offline side (formats, visible, toml_errors) and its page templates. It reads a study
bundle and never imports `search`, torch or numba (matplotlib only for the report's figures, where installed)."""
