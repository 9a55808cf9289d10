"""The closed loop on top of the pipeline: the residual of an
identification, the catalogue of effects the model lacks, their attribution,
the test of each candidate and the verdict."""
