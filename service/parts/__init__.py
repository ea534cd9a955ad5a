"""Parts: recipes (part types), their verdicts and statistical process control."""
