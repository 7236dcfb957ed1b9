"""The check application (``warp-ccd check``, ``check_usd``): frames of a USD animation checked for
interpenetration, penetrating or touching told by the surfaces, its report, overlay, many files and Ray."""
