"""The simulator's fence without ROS (migration_manager.core.fence): velocity commands of a managed move_base instance are
obeyed only while it holds the lease; commands without the instance header are obeyed as before."""
from migration_manager.core.fence import INSTANCE_HEADER, CommandFence
from migration_manager.core.lease import Answer, Grantor

ROBOT = {INSTANCE_HEADER: 'move_base@robot'}
CLOUD = {INSTANCE_HEADER: 'move_base@cloud'}


def test_the_header_name_is_the_managed_instances():
    from migration_manager.instance import INSTANCE_HEADER as used_by_instances
    assert INSTANCE_HEADER == used_by_instances


def test_unmanaged_commands_pass_and_nothing_is_fenced_before_a_lease_is_heard():
    fence = CommandFence('move_base')
    assert fence.accept(None) and fence.accept({}) and fence.accept({'callerid': '/teleop'})
    assert fence.accept(ROBOT) and fence.accept(CLOUD)                 # no lease heard: nothing is managed
    assert fence.holder() == 'unmanaged' and fence.dropped == 0


def test_only_the_holder_commands_through_a_migration():
    grantor = Grantor('move_base', duration=0.6, margin=0.15)
    fence = CommandFence('move_base')
    grantor.promote('move_base@robot', now=0.0)
    fence.on_lease(grantor.request('move_base@robot', grantor.term, 1, now=0.0))
    assert fence.accept(ROBOT) and not fence.accept(CLOUD)
    assert fence.accept(None)                                          # teleop still drives

    # freeze the robot's instance, release, promote the cloud's: its first granted renewal moves the fence
    grantor.release('move_base@robot', grantor.term)
    fence.on_lease(grantor.announcement())
    assert not fence.accept(ROBOT) and not fence.accept(CLOUD)         # between holders: nobody
    grantor.promote('move_base@cloud', now=1.0)
    fence.on_lease(grantor.request('move_base@cloud', grantor.term, 7, now=1.0))
    assert fence.accept(CLOUD) and not fence.accept(ROBOT)
    assert fence.holder() == 'move_base@cloud' and fence.dropped == 4

    # a late answer of an older term (queued in a link) does not move the fence back
    fence.on_lease(Answer('move_base', 1, 'move_base@robot', 2, True, 0.6))
    assert not fence.accept(ROBOT) and fence.accept(CLOUD)


def test_other_modules_leases_and_instances_are_not_this_fences():
    fence = CommandFence('move_base')
    fence.on_lease(Answer('mfg', 5, 'mfg@cloud', 0, False, 0.6))
    assert fence.holder() == 'unmanaged'
    fence.on_lease(Answer('move_base', 2, 'move_base@cloud', 0, False, 0.6))
    assert fence.accept({INSTANCE_HEADER: 'mfg@robot'})                  # not a move_base instance
    assert not fence.accept(ROBOT)
