"""The offline side of Foil, in layers that import only downwards:

    sim -> agents -> solvers -> clips -> bundle -> cli

`sim` is the crowd world and the coupled simulator, `agents` the DS-RNN robots and their training, `solvers` the
scenario search and its summaries, `clips` the renderer, `bundle` a study's clips and manifest, `cli` the `foil`
command. docs/architecture.md draws the whole picture, the survey server (`app`) included.
"""
