"""What DriftLab writes for people: a job's and a study's report (markdown and figures), the paper's plots,
trajectory files (CSV and JSON). Edges over core/ and db/, outside core/."""
