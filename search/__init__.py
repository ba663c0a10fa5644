"""The offline side of Foil, in layers that import only downwards:

    sim -> agents -> solvers -> gym -> clips -> highway -> bundle -> cli

`sim` is the crowd world and the coupled simulator, `agents` the DS-RNN robots and their training, `solvers` the
scenario search and its summaries, `gym` any Gymnasium environment as a world, `clips` the renderer, `highway`
highway driving as the second domain, `bundle` a study's clips and manifest, `cli` the `foil` command (which also
lists the server's commands from `app.cli`). docs/architecture.md draws the whole picture, the survey server
(`app`) included.
"""
