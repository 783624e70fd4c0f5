"""The REST API's routers: jobs (and their evaluations), single evaluations, and the landing pages."""
