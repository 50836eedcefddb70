"""The CPU dense path: silhouettes, visual hull, plane-sweep and PatchMatch stereo, Poisson."""
