"""The clips layer: the toolkit every world's renderer draws and encodes its clips with (an H.264 clip, a poster
and a contact sheet), and reels of several clips. It reads summaries; it never runs a search."""
