"""What a reconstruction hands on: PLY/NPZ/report files, relit renders, evaluation, plots."""
