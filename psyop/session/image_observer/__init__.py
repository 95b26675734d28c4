"""The image-computable simulated observer's parts: its eye (optics, eccentricity), the frames it is shown
(rendered by the session's scene renderer) and its internal response to an interval's frames.
psyop.session.responses.image_observer answers trials with them."""
