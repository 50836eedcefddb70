"""Camera poses: known poses, a printed ChArUco board under the object, or SfM with pycolmap."""
