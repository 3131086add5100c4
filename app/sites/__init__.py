"""Learning from the site (docs/estimates.md#sites): the estimates recomputed from the execution
reports (service), the sites and their runs, and the rebuild of the outcome table from the
record."""
