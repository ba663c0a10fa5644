"""The bundle layer: a study file's [build] table turned into the clips the survey serves (evaluations, searches,
renders, the audited manifest.json and a gallery for the researcher). The top of the offline stack: it calls the
agents, solvers and clips layers as libraries."""
