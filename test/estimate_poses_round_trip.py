"""One EstimatePoses goal from an rclpy ActionClient to an ActionServer in this process; prints what the client
received as JSON. test_interfaces.py runs it in an environment with nothing ROS set up."""
import json
import math
import threading

import rclpy
from geometry_msgs.msg import Pose
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import MultiThreadedExecutor
from sensor_msgs.msg import Image

from idpose_interfaces.action import EstimatePoses
from idpose_interfaces.msg import ViewEstimate

FEEDBACK_STEPS = 3


def execute(goal_handle) -> EstimatePoses.Result:
    """Feedback in FEEDBACK_STEPS steps, then one ViewEstimate per goal image, the anchor's frame on the poses."""
    images = goal_handle.request.images
    for step in range(1, FEEDBACK_STEPS + 1):
        goal_handle.publish_feedback(EstimatePoses.Feedback(
            stage="refinement", progress=step / FEEDBACK_STEPS, forward_samples=16 * step,
            seconds_elapsed=0.5 * step, seconds_remaining=-1.0 if step == 1 else 0.5 * (FEEDBACK_STEPS - step)))
    result = EstimatePoses.Result(error_code=EstimatePoses.Result.SUCCEEDED, run_id=7, object_distance=0.8,
                                  distance_source="parameter", anchor_polar_deg=75.0,
                                  anchor_polar_source="parameter", forward_samples=48, seconds=1.5)
    result.poses.header = images[0].header
    for k, image in enumerate(images):
        pose = Pose()
        pose.position.x = float(k)
        result.poses.poses.append(pose)
        result.views.append(ViewEstimate(header=image.header, pose=pose, confidence=1.0 if k == 0 else 0.25,
                                         ambiguous=k > 0, roll_deg=math.nan, polar_deg=math.nan,
                                         mask_method="alpha", polar_source="", object_distance=math.nan,
                                         touches_border=False, reliable=k == 0))
    goal_handle.succeed()
    return result


def wait(future, what: str):
    """The future's result, once the executor thread has completed it (within 30 s)."""
    event = threading.Event()
    future.add_done_callback(lambda _: event.set())
    assert event.wait(30), f"no {what} within 30 s"
    return future.result()


def send_goal(client: ActionClient) -> dict:
    """Send a two-image goal and wait for its result; what came back, JSON-ready."""
    assert client.wait_for_server(timeout_sec=30), "no action server"
    images = []
    for k in range(2):
        image = Image(height=2, width=2, encoding="rgb8", step=6, data=bytes(12))
        image.header.frame_id = f"camera_{k}"
        images.append(image)
    feedback = []
    handle = wait(client.send_goal_async(EstimatePoses.Goal(images=images, preset=""),
                                         feedback_callback=lambda message: feedback.append(message.feedback)),
                  "goal response")
    assert handle.accepted, "goal rejected"
    result = wait(handle.get_result_async(), "result").result
    return {
        "feedback": [[f.stage, round(f.progress, 3), f.forward_samples, f.seconds_remaining] for f in feedback],
        "error_code": result.error_code, "run_id": result.run_id, "frame": result.poses.header.frame_id,
        "poses_x": [p.position.x for p in result.poses.poses],
        "views": [[v.header.frame_id, v.confidence, v.ambiguous, v.reliable, math.isnan(v.polar_deg)]
                  for v in result.views],
    }


def main() -> None:
    rclpy.init()
    server_node, client_node = rclpy.create_node("round_trip_server"), rclpy.create_node("round_trip_client")
    server = ActionServer(server_node, EstimatePoses, "estimate_poses", execute)
    client = ActionClient(client_node, EstimatePoses, "estimate_poses")
    executor = MultiThreadedExecutor(num_threads=2)
    for node in (server_node, client_node):
        executor.add_node(node)
    spinner = threading.Thread(target=executor.spin)
    spinner.start()
    try:
        print(json.dumps(send_goal(client)))
    finally:  # stop spinning before anything is destroyed, or the process aborts on exit
        executor.shutdown()
        spinner.join()
        client.destroy()
        server.destroy()
        for node in (server_node, client_node):
            node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
