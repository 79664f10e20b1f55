"""Ways to solve the tracking problem's QPs: condensed (dense) and sparse (stage-wise)."""
