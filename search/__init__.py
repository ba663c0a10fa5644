"""The offline side of Foil, in layers that import only downwards:

    sim -> agents -> solvers -> clips -> crowd -> gym -> highway -> bundle -> cli

`sim` is the crowd world's simulator, `agents` the DS-RNN robots and their training, `solvers` the world-free
search (the `Problem` protocol, the solvers, summaries checked by `foil verify`) and the `Domain` interface every
world implements, `clips` the drawing and encoding of clips, `crowd` the crowd world as a domain, `gym` any
Gymnasium environment as a domain, `highway` highway driving as a Gymnasium domain with its own agents, `bundle`
a study's clips and manifest, `cli` the `foil` command (which also lists the server's commands from `app.cli`).
Above `solvers`, every command reaches a world through its domain only. docs/architecture.md draws the whole
picture, the survey server (`app`) included.
"""
