"""Stage 4, refinement: map-to-map alignment (the baseline's extrinsic) and the joint estimate refined on its poses."""
