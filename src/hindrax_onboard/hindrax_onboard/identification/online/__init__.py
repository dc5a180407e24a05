"""The identification campaign as it runs: executive, steps, excitation, manoeuvres, online estimator, node."""
