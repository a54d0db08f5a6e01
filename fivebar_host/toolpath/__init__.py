"""Drawing input and geometry: SVG and G-code readers, layout, path order, segmentation."""
