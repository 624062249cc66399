# SPDX-License-Identifier: GPL-3.0-or-later
"""What every Relight operator shares: a ``poll()`` that says why the operator is disabled
(the pattern of node_wrangler's ``NWBase``), shown as the button's tooltip."""


class RelightOperator:
    """Mixin for ``bpy.types.Operator`` subclasses: override :meth:`disabled_reason`."""

    @classmethod
    def poll(cls, context):
        reason = "No active scene" if getattr(context, "scene", None) is None else \
            cls.disabled_reason(context)
        if reason:
            cls.poll_message_set(reason)
            return False
        return True

    @classmethod
    def disabled_reason(cls, context):
        """A sentence saying why the operator cannot run now (the scene exists), or None."""
        return None
