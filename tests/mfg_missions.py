"""The corridor mission without heaters (mfg only patrols: no search, no end of the mission), for mfg's tests."""
import os

import yaml


def patrol_only_mission(ros, workspace, tmp_path, log_name, *args):
    """Start it on the session's master (``args``: more mission.launch arguments); (process, report folder)."""
    with open(os.path.join(workspace, 'config', 'scenarios', 'corridor.yaml')) as stream:
        scenario = yaml.safe_load(stream)
    scenario['temperature_field']['sources'] = []
    scenario_file = str(tmp_path / 'patrol_only.yaml')
    with open(scenario_file, 'w') as stream:
        yaml.safe_dump(scenario, stream)
    report = str(tmp_path / 'report')
    proc = ros.master.run(['rosrun', 'cnr_bringup', 'cnr_launch', '--until', 'mission_monitor',
                           'cnr_mission', 'mission.launch', 'monitor_required:=false', f'scenario_file:={scenario_file}',
                           f'map:={workspace}/maps/corridor.yaml', f'report_dir:={report}', f'store:={report}/store.tsv',
                           *args], log_name=log_name)
    return proc, report
