"""What a person reads: the trend chart, the HTML report and the Prometheus metrics."""
