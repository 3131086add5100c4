"""Learning from the site (SPEC 17): the estimates recomputed from the execution reports
(service), the sites and their runs, and the rebuild of the outcome table from the record."""
