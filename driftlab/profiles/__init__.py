"""The car profiles DriftLab ships: each ``<plant>-vehicle<id>.json`` is the file ``driftlab calibrate --out`` wrote,
every profile in it naming the command that made it (``command``) and the release (``driftlab_version``). A job of
that car takes one where the database has no profile of its own for the job's drift (driftlab.services.profiles)."""
