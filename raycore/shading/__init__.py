"""From hits to pixels: the visible surface (gather), Blinn-Phong shading
and textures, and the image's pixel writes."""
