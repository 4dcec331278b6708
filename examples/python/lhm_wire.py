"""Decoders for the lhm wire messages (protos/proto/lhm/v1/lhm.proto) and a numpy runner for a
published policy, with no generated code: a protobuf reader of the few field kinds the messages
use, a safetensors reader, and the network's forward pass as the .proto documents it
(PolicyWeights.config_json).

Needs numpy. The zenoh scripts beside it also need the `eclipse-zenoh` package.
"""

import json
import math
import struct

import numpy as np

# Field number -> (name, kind). Kinds: "u" varint, "f64" double, "f32" float, "str", "bytes",
# "pf32" packed floats, "pbool" packed bools, "msg:<Name>", "rmsg:<Name>" repeated message.
SCHEMAS = {
    "Normalizer": {
        1: ("count", "f64"),
        2: ("mean", "pf32"),
        3: ("var", "pf32"),
        4: ("epsilon", "f64"),
        5: ("clip", "f64"),
    },
    "PolicyWeights": {
        1: ("schema_version", "u"),
        2: ("run_id", "str"),
        3: ("role", "u"),
        4: ("version", "u"),
        5: ("safetensors", "bytes"),
        6: ("obs_normalizer", "msg:Normalizer"),
        7: ("amp_normalizer", "msg:Normalizer"),
        8: ("config_json", "str"),
    },
    "EpisodeStats": {
        1: ("episode_return", "f32"),
        2: ("length", "u"),
        3: ("cycles_attempted", "u"),
        4: ("cycles_succeeded", "u"),
        5: ("final_placement_error_m", "pf32"),
    },
    "TrajectoryChunk": {
        1: ("schema_version", "u"),
        2: ("run_id", "str"),
        3: ("actor_id", "str"),
        4: ("role", "u"),
        5: ("policy_version", "u"),
        6: ("chunk_seq", "u"),
        7: ("env_index", "u"),
        8: ("num_steps", "u"),
        9: ("obs_dim", "u"),
        10: ("act_dim", "u"),
        11: ("amp_dim", "u"),
        12: ("observations", "pf32"),
        13: ("actions", "pf32"),
        14: ("log_probs", "pf32"),
        15: ("values", "pf32"),
        16: ("rewards", "pf32"),
        17: ("dones", "pbool"),
        18: ("truncated", "pbool"),
        19: ("truncation_values", "pf32"),
        20: ("amp_features", "pf32"),
        21: ("bootstrap_value", "f32"),
        22: ("episodes", "rmsg:EpisodeStats"),
    },
}

REPEATED = ("pf32", "pbool")


class WireError(ValueError):
    pass


def _varint(buf, i):
    shift, value = 0, 0
    while True:
        if i >= len(buf):
            raise WireError("truncated varint")
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        if b < 0x80:
            return value, i
        shift += 7
        if shift > 63:
            raise WireError("varint longer than 10 bytes")


def decode(buf, name):
    """Decodes `buf` as message `name` into a dict (unknown fields are skipped, as protobuf
    readers do; absent scalars are 0/""/empty, as proto3 has it)."""
    schema = SCHEMAS[name]
    out = {}
    for field, kind in schema.values():
        if kind in REPEATED:
            out[field] = []
        elif kind.startswith("rmsg:"):
            out[field] = []
        elif kind.startswith("msg:"):
            out[field] = None
        elif kind in ("str",):
            out[field] = ""
        elif kind == "bytes":
            out[field] = b""
        else:
            out[field] = 0
    buf = memoryview(buf).tobytes() if not isinstance(buf, bytes) else buf
    i = 0
    while i < len(buf):
        key, i = _varint(buf, i)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(buf, i)
            payload = value
        elif wire == 1:
            if i + 8 > len(buf):
                raise WireError("truncated 64-bit field")
            payload = buf[i : i + 8]
            i += 8
        elif wire == 5:
            if i + 4 > len(buf):
                raise WireError("truncated 32-bit field")
            payload = buf[i : i + 4]
            i += 4
        elif wire == 2:
            n, i = _varint(buf, i)
            if i + n > len(buf):
                raise WireError(f"field {number}: length {n} runs past the end")
            payload = buf[i : i + n]
            i += n
        else:
            raise WireError(f"field {number}: unsupported wire type {wire}")
        if number not in schema:
            continue
        field, kind = schema[number]
        if kind == "u":
            out[field] = payload
        elif kind == "f64":
            out[field] = struct.unpack("<d", payload)[0]
        elif kind == "f32":
            out[field] = struct.unpack("<f", payload)[0]
        elif kind == "str":
            out[field] = payload.decode("utf-8")
        elif kind == "bytes":
            out[field] = payload
        elif kind == "pf32":
            if wire == 2:
                if len(payload) % 4:
                    raise WireError(f"{field}: {len(payload)} bytes is not whole floats")
                out[field].extend(np.frombuffer(payload, dtype="<f4").tolist())
            else:
                out[field].append(struct.unpack("<f", payload)[0])
        elif kind == "pbool":
            if wire == 2:
                out[field].extend(bool(b) for b in payload)
            else:
                out[field].append(bool(payload))
        elif kind.startswith("msg:"):
            out[field] = decode(payload, kind[4:])
        elif kind.startswith("rmsg:"):
            out[field].append(decode(payload, kind[5:]))
    return out


def read_safetensors(blob):
    """name -> numpy array from a safetensors file held in memory."""
    if len(blob) < 8:
        raise WireError("safetensors: shorter than its header length")
    (n,) = struct.unpack("<Q", blob[:8])
    header = json.loads(blob[8 : 8 + n])
    data = blob[8 + n :]
    dtypes = {"F32": "<f4", "F64": "<f8", "F16": "<f2"}
    out = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        start, end = info["data_offsets"]
        out[name] = np.frombuffer(data[start:end], dtype=dtypes[info["dtype"]]).reshape(
            info["shape"]
        )
    return out


def _normalizer(norm):
    """(mean, std, clip) from config_json's f64 normaliser, or None."""
    if norm is None:
        return None
    mean = np.asarray(norm["mean"], dtype=np.float64)
    std = np.sqrt(np.asarray(norm["var"], dtype=np.float64) + norm["epsilon"])
    return mean, std, norm["clip"]


class Policy:
    """A published policy: mean actions, log-probabilities and values, with numpy."""

    def __init__(self, weights_message):
        msg = decode(weights_message, "PolicyWeights")
        self.run_id, self.version = msg["run_id"], msg["version"]
        config = json.loads(msg["config_json"])
        spec = config["spec"]
        self.obs_dim, self.act_dim = spec["obs_dim"], spec["act_dim"]
        ac = spec["actor_critic"]
        self.activation = ac["policy"]["mlp"]["activation"]
        self.value_activation = ac["value"]["activation"]
        tensors = read_safetensors(msg["safetensors"])
        self.mean_layers = self._layers(tensors, "policy.mean")
        self.value_layers = self._layers(tensors, "value")
        log_std = ac["policy"]["log_std"]
        if "fixed" in log_std:
            self.log_std = np.full(self.act_dim, log_std["fixed"], dtype=np.float64)
        else:
            self.log_std = tensors["policy.log_std"].astype(np.float64).reshape(-1)
        self.obs_norm = _normalizer(config.get("obs_norm"))
        value_norm = config.get("value_norm")
        self.value_scale = (
            (value_norm["mean"][0], math.sqrt(value_norm["var"][0] + value_norm["epsilon"]))
            if value_norm
            else (0.0, 1.0)
        )

    @staticmethod
    def _layers(tensors, prefix):
        layers, i = [], 0
        while f"{prefix}.layers.{i}.weight" in tensors:
            w = tensors[f"{prefix}.layers.{i}.weight"].astype(np.float64)
            b = tensors[f"{prefix}.layers.{i}.bias"].astype(np.float64)
            layers.append((w, b))
            i += 1
        if not layers:
            raise WireError(f"no {prefix}.layers.* tensors")
        return layers

    @staticmethod
    def _act(z, kind):
        if kind == "relu":
            return np.maximum(z, 0.0)
        return np.where(z > 0.0, z, np.expm1(np.minimum(z, 0.0)))  # ELU, alpha 1

    def _input(self, obs):
        x = np.asarray(obs, dtype=np.float64).reshape(-1, self.obs_dim)
        if self.obs_norm is not None:
            mean, std, clip = self.obs_norm
            x = np.clip((x - mean) / std, -clip, clip)
        return x

    def _mlp(self, x, layers, kind):
        for w, b in layers[:-1]:
            x = self._act(x @ w.T + b, kind)
        w, b = layers[-1]
        return x @ w.T + b

    def mean_actions(self, obs):
        """Deterministic actions, rows of act_dim."""
        return self._mlp(self._input(obs), self.mean_layers, self.activation)

    def log_prob(self, obs, actions):
        """Log-density of `actions` under the Gaussian policy, one per row (nats)."""
        mu = self.mean_actions(obs)
        a = np.asarray(actions, dtype=np.float64).reshape(mu.shape)
        z = (a - mu) / np.exp(self.log_std)
        return -0.5 * (z * z).sum(axis=1) - self.log_std.sum() - 0.5 * self.act_dim * math.log(
            2.0 * math.pi
        )

    def values(self, obs):
        out = self._mlp(self._input(obs), self.value_layers, self.value_activation)[:, 0]
        mean, std = self.value_scale
        return out * std + mean
