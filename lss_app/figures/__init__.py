"""The figures of the application: matplotlib lives here, not in the libraries."""
