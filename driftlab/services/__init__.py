"""What the REST routes and the CLI both call (one implementation for both edges)."""
