"""Point queries on the device: occupancy (:func:`inside`) and a conservative signed distance
(:func:`distance`), both computed from the scene's tape by ``query.cl``."""

from .point_queries import distance, inside

__all__ = ["distance", "inside"]
