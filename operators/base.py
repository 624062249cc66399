# SPDX-License-Identifier: GPL-3.0-or-later
"""What every Relight operator shares: a ``poll()`` that says why the operator is disabled
(the pattern of node_wrangler's ``NWBase``), shown as the button's tooltip."""


class RelightOperator:
    """Mixin for ``bpy.types.Operator`` subclasses: override :meth:`disabled_reason`."""

    @classmethod
    def poll(cls, context):
        reason = cls.disabled_reason(context)
        if reason:
            cls.poll_message_set(reason)
            return False
        return True

    @classmethod
    def disabled_reason(cls, context):
        """A sentence saying why the operator cannot run now, or None."""
        if getattr(context, "scene", None) is None:
            return "No active scene"
        return None
