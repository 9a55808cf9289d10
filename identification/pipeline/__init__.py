"""The identification pipeline: its stages (the global search, window
growth, the start of a joint fit, local refinement, the shrink stage,
intervals and profiles), the driver that runs them from the records with
one Settings (driver.identify_records, the front door of `lss identify`)
and the campaign over many sorters."""
