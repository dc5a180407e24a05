"""What is said about a fit: verdicts, identification.yaml, vehicle match, reports and predictions."""
