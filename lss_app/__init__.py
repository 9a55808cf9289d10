"""The application above the two libraries (lss_fmu, identification): the `lss`
command line, `make demo`, the reports and the figures."""
