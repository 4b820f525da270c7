"""What the twin and its clients share, defined once.

The cell description (:mod:`interfaces.cell`), the ROS contract (:mod:`interfaces.contract`),
the sorting events (:mod:`interfaces.events`), the metric table (:mod:`interfaces.metrics`), the
project's base error (:mod:`interfaces.errors`) and the small file and YAML helpers every
package uses. It imports nothing from ``twin``, ``control``, ``experiments``, ``meshgen`` or
``fmus``: each of them, and a controller running on a real robot's computer, may import it.
The ROS 2 message package lives beside it in ``interfaces/cdw_interfaces``.
"""
