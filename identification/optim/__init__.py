"""The optimisers: Complex-RF (serial), Complex-RFP (several candidates per
round, local processes or Dask), their result objects and the evaluation
journal that makes a run resumable. Nothing here knows what a sorter is."""
