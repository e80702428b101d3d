"""The full-grid evaluation, the robustness sweeps, and the reports and figures they write."""
