"""Who may publish what: one description, turned into Zenoh's own authentication and access control.

A secured robot has a *secrets folder* (`hri secure init DIR`):
- `DIR/passwords`: `user:password` lines, the router's Zenoh user/password dictionary (mode 0600);
- `DIR/users.json`: `{"users": {user: [role, ...]}, "roles": {...optional extra roles...}}`.

The router (`hri router --secure DIR`) authenticates every session with Zenoh's `usrpwd` and enforces the
access-control rules generated here from ROLES, which are derived from the stack's declaration (common/stack.py):
each node publishes exactly the keys of its outputs (camera -> camera/*/frame and camera/*/depth, … fusion ->
fusion/command and fusion/clarification) and reads exactly those of its inputs; the `reader` role (the `cli`
user: hri echo/list/stats/record, a planner) only reads. Everything not allowed is denied. A process opens its
session as `--user NAME` (default: the service's own name, `cli` for the hri command) with the password it finds
for that user in `DIR/passwords` — a machine can be given only its own line. Pure: nothing here opens a session.

Several robots on one router (a site): `hri secure init SITE --robot robot1`, then `--robot robot2`, gives each
robot its own users (`robot1-camera`, …, `robot1-cli`) bound to its prefix (users.json "prefixes"); the router
(`hri router --secure SITE`) lets each user publish, subscribe and learn of subscribers only under its own
robot's prefix. A process started with `--prefix robot1` logs in as `robot1-NAME` when the folder has that user.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import socket
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import common.stack as stack

PASSWORDS = "passwords"
USERS = "users.json"
TLS = "tls"  # DIR/tls/: ca.pem (every process trusts it), router.pem + router-key.pem (the router's identity)


@dataclass(frozen=True)
class Role:
    publish: tuple[str, ...] = ()  # key expressions under the prefix this role may put on
    subscribe: tuple[str, ...] = ()  # ... may receive
    service: str | None = None  # declares hri/alive/{service}/* and answers hri/stats/{service}/*

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Role":
        unknown = set(d) - {"publish", "subscribe", "service"}
        if unknown:
            raise SecurityError(f"unknown role field(s) {sorted(unknown)}; a role has publish, subscribe, service")
        return cls(tuple(d.get("publish", ())), tuple(d.get("subscribe", ())), d.get("service"))


def stack_roles() -> dict[str, Role]:
    """The roles of the stack, derived from common/stack.py: a node publishes exactly its outputs' keys (and its
    fixed keys), reads exactly its inputs' keys and answers as the service of its name; a client publishes its
    outputs' keys (and its fixed keys) and the reader reads everything. Key expressions are under the prefix,
    one '*' per placeholder."""
    roles: dict[str, Role] = {}
    for n in stack.NODES:
        roles[n.name] = Role(
            publish=tuple(dict.fromkeys([*(stack.topic(t).wildcard() for t in n.outputs), *n.fixed_keys])),
            subscribe=tuple(dict.fromkeys(stack.topic(i.topic).wildcard() for i in n.inputs)),
            service=n.name,
        )
    for c in stack.CLIENTS:
        roles[c.name] = Role(
            publish=tuple(dict.fromkeys([*(stack.topic(t).wildcard() for t in c.outputs), *c.fixed_keys])),
            subscribe=("**",) if c.reads_everything else (),
        )
    return roles


def stack_default_users() -> dict[str, list[str]]:
    """The users `hri secure init` creates: each node logs in as itself; the clients that name a user."""
    return {**{n.name: [n.name] for n in stack.NODES}, **{c.user: [c.name] for c in stack.CLIENTS if c.user}}


ROLES: dict[str, Role] = stack_roles()
SERVICE_USERS = tuple(n.name for n in stack.NODES)
DEFAULT_USERS: dict[str, list[str]] = stack_default_users()


class SecurityError(ValueError):
    pass


@dataclass
class Secrets:
    folder: Path
    users: dict[str, list[str]]
    roles: dict[str, Role] = field(default_factory=lambda: dict(ROLES))
    prefixes: dict[str, str] = field(default_factory=dict)  # user -> its robot's prefix (absent: the router's)

    def prefix_of(self, user: str, default: str) -> str:
        return self.prefixes.get(user, default)

    @property
    def passwords_file(self) -> Path:
        return self.folder / PASSWORDS


def read_passwords(path: Path) -> dict[str, str]:
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise SecurityError(
            f"cannot read the password file {path}: {exc.strerror}; create the secrets folder "
            f"with `hri secure init {path.parent}`"
        ) from None
    out = {}
    for line in lines:
        if line.strip() and not line.startswith("#"):
            user, sep, password = line.partition(":")
            if not sep or not user or not password:
                raise SecurityError(f"{path}: every line must be user:password")
            out[user.strip()] = password.strip()
    return out


def login_user(folder: str | Path, user: str, prefix: str) -> str:
    """The user a process of robot `prefix` logs in as: `PREFIX-USER` where the folder has it (a site's robot
    users, `hri secure init --robot`), else `user`."""
    robot_user = f"{prefix.replace('/', '-')}-{user}"
    if prefix != "hri" and robot_user in read_passwords(Path(folder) / PASSWORDS):
        return robot_user
    return user


def password_for(folder: str | Path, user: str) -> str:
    path = Path(folder) / PASSWORDS
    passwords = read_passwords(path)
    if user not in passwords:
        raise SecurityError(
            f"no password for user {user!r} in {path} (users there: {', '.join(sorted(passwords))}); "
            f"give --user NAME, or add the user with `hri secure init {folder} --user {user}:ROLE`"
        )
    return passwords[user]


def read_secrets(folder: str | Path) -> Secrets:
    folder = Path(folder)
    try:
        doc = json.loads((folder / USERS).read_text())
    except OSError as exc:
        raise SecurityError(
            f"cannot read {folder / USERS}: {exc.strerror}; create the secrets folder with `hri secure init {folder}`"
        ) from None
    except json.JSONDecodeError as exc:
        raise SecurityError(f"{folder / USERS} is not valid JSON: {exc}") from None
    roles = dict(ROLES)
    for name, role in doc.get("roles", {}).items():
        roles[name] = Role.from_dict(role)
    users = {u: list(r) for u, r in doc.get("users", {}).items()}
    prefixes = {u: str(p) for u, p in doc.get("prefixes", {}).items()}
    for user, their_roles in users.items():
        unknown = [r for r in their_roles if r not in roles]
        if unknown:
            raise SecurityError(
                f"{folder / USERS}: user {user!r} has unknown role(s) {unknown}; roles: {', '.join(sorted(roles))}"
            )
    return Secrets(folder, users, roles, prefixes)


def init_secrets(
    folder: str | Path, extra_users: dict[str, list[str]] | None = None, robot: str | None = None
) -> Secrets:
    """Create (or extend) a secrets folder: a random password for every user that has none yet.

    `robot`: a prefix; the default users (and `extra_users`) are added as `ROBOT-NAME`, allowed only under it."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    users: dict[str, list[str]] = {} if robot else dict(DEFAULT_USERS)
    prefixes: dict[str, str] = {}
    if (folder / USERS).exists():
        old = read_secrets(folder)
        users.update(old.users)
        prefixes.update(old.prefixes)
    if robot:
        robot = robot.strip("/")
        if not robot or robot == "hri" or any(c in robot for c in "*$?#"):
            raise SecurityError(f"--robot {robot!r}: give the robot's prefix (e.g. robot1), not the default 'hri'")
        for name, their_roles in {**DEFAULT_USERS, **(extra_users or {})}.items():
            user = f"{robot.replace('/', '-')}-{name}"
            users[user] = list(their_roles)
            prefixes[user] = robot
    else:
        users.update(extra_users or {})
    for user, their_roles in users.items():
        unknown = [r for r in their_roles if r not in ROLES]
        if unknown:
            raise SecurityError(f"user {user!r}: unknown role(s) {unknown}; roles: {', '.join(sorted(ROLES))}")
    passwords = read_passwords(folder / PASSWORDS) if (folder / PASSWORDS).exists() else {}
    for user in users:
        passwords.setdefault(user, secrets.token_urlsafe(24))
    _write_private(folder / PASSWORDS, "".join(f"{u}:{p}\n" for u, p in passwords.items()))
    doc: dict[str, Any] = {"users": users}
    if prefixes:
        doc["prefixes"] = prefixes
    _write_private(folder / USERS, json.dumps(doc, indent=2) + "\n")
    return read_secrets(folder)


def tls_files(folder: str | Path) -> dict[str, Path]:
    """The TLS files of a secrets folder that exist: ca, cert, key."""
    d = Path(folder) / TLS
    files = {"ca": d / "ca.pem", "cert": d / "router.pem", "key": d / "router-key.pem"}
    return {k: p for k, p in files.items() if p.exists()}


def make_tls(folder: str | Path, hosts: list[str]) -> list[Path]:
    """A private CA and a router certificate for `hosts` (names or IPs) with the openssl command, ECDSA P-256,
    10 years. The CA key stays in the folder, to issue a new router certificate later."""
    if shutil.which("openssl") is None:
        raise SecurityError(
            "making TLS certificates needs the openssl command (apt-get install openssl), or "
            "put your own ca.pem, router.pem and router-key.pem in the folder's tls/"
        )
    d = Path(folder) / TLS
    d.mkdir(exist_ok=True)
    os.chmod(d, 0o700)
    hosts = hosts or ["localhost", "127.0.0.1", socket.gethostname()]
    san = ",".join(f"IP:{h}" if _is_ip(h) else f"DNS:{h}" for h in dict.fromkeys(hosts))
    ext = d / "router.ext"
    ext.write_text(
        f"subjectAltName={san}\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth\n"
    )
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    steps = []
    if not (d / "ca.pem").exists():
        steps.append(
            [
                "req",
                "-x509",
                *ec,
                "-keyout",
                "ca-key.pem",
                "-out",
                "ca.pem",
                "-days",
                "3650",
                "-subj",
                "/CN=hri-fusion robot CA",
            ]
        )
    steps += [
        ["req", *ec, "-keyout", "router-key.pem", "-out", "router.csr", "-subj", "/CN=hri-router"],
        [
            "x509",
            "-req",
            "-in",
            "router.csr",
            "-CA",
            "ca.pem",
            "-CAkey",
            "ca-key.pem",
            "-CAcreateserial",
            "-out",
            "router.pem",
            "-days",
            "3650",
            "-extfile",
            "router.ext",
        ],
    ]
    for step in steps:
        res = subprocess.run(["openssl", *step], cwd=d, capture_output=True, text=True)
        if res.returncode != 0:
            raise SecurityError(f"openssl {step[0]} failed: {res.stderr.strip()[-300:]}")
    for key in ("ca-key.pem", "router-key.pem"):
        os.chmod(d / key, 0o600)
    (d / "router.csr").unlink()
    return [d / "ca.pem", d / "router.pem"]


def _is_ip(host: str) -> bool:
    import ipaddress

    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        return False


def _write_private(path: Path, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.chmod(path, 0o600)


def access_control(sec: Secrets, prefix: str) -> dict[str, Any]:
    """Zenoh's `access_control` section: deny by default, allow what each user's roles describe, under the
    user's robot's prefix (`prefix`, the router's, unless users.json binds the user to another)."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    robots = sorted({sec.prefix_of(u, prefix) for u in sec.users}, key=lambda p: (p != prefix, p))
    for robot in robots:
        members = {u: r for u, r in sec.users.items() if sec.prefix_of(u, prefix) == robot}
        _robot_rules(sec.roles, members, robot, "" if robot == prefix else f"@{robot}", rules, subjects, policies)
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def _robot_rules(
    roles: dict[str, Role],
    users: dict[str, list[str]],
    prefix: str,
    tag: str,
    rules: list[dict[str, Any]],
    subjects: list[dict[str, Any]],
    policies: list[dict[str, Any]],
) -> None:
    """The rules of one robot's users (rule and subject ids end with `tag` on a site of several robots)."""

    def keys(exprs: tuple[str, ...]) -> list[str]:
        return [f"{prefix}/{e}" for e in exprs]

    def allow(rule_id: str, flow: str, messages: list[str], exprs: tuple[str, ...]) -> str:
        rules.append(
            {
                "id": rule_id + tag,
                "permission": "allow",
                "flows": [flow],
                "messages": messages,
                "key_exprs": keys(exprs),
            }
        )
        return rule_id + tag

    # every authenticated user may see who is alive and ask for stats
    common = [
        allow(
            "observe",
            "ingress",
            ["liveliness_query", "declare_liveliness_subscriber", "query"],
            ("alive/**", "stats/**"),
        ),
        allow(
            "observe-answers", "egress", ["liveliness_token", "reply", "declare_queryable"], ("alive/**", "stats/**")
        ),
        # A zenoh client sends a sample only where it knows of a subscriber, so publishers must be told of
        # them. A declaration passes only if a rule's key *includes* it, and subscriptions are often wider
        # than one publisher's keys (hri/speech/*/transcript vs speech/kbd/transcript, hri/** vs
        # fusion/**): everyone may learn of every subscription under the prefix. Samples stay filtered.
        allow("learn-subscribers", "egress", ["declare_subscriber"], ("**",)),
    ]
    if users:
        subjects.append({"id": "everyone" + tag, "usernames": sorted(users)})
        policies.append({"rules": common, "subjects": ["everyone" + tag]})
    for name, role in sorted(roles.items()):
        members = sorted(u for u, r in users.items() if name in r)
        if not members:
            continue
        ids = []
        if role.publish:
            # "reply": a recovering publisher answers from its cache with the samples' own keys
            ids.append(allow(f"{name}-publish", "ingress", ["put", "delete", "reply"], role.publish))
            # a recovering publisher (zenoh.ext AdvancedPublisher: fusion's commands) keeps its cache, heartbeat and
            # liveliness under KEY/@adv/pub/..., which no wildcard reaches: allowed for its own keys only
            adv = tuple(f"{e}/@adv/**" for e in role.publish)
            ids.append(
                allow(
                    f"{name}-recovering",
                    "ingress",
                    [
                        "put",
                        "declare_queryable",
                        "reply",
                        "liveliness_token",
                        "declare_liveliness_subscriber",
                        "liveliness_query",
                    ],
                    adv,
                )
            )
            ids.append(
                allow(f"{name}-recovering-peers", "egress", ["query", "declare_subscriber", "liveliness_token"], adv)
            )
        if role.subscribe:
            ids.append(allow(f"{name}-subscribe", "ingress", ["declare_subscriber"], role.subscribe))
            ids.append(allow(f"{name}-receive", "egress", ["put", "delete", "reply"], role.subscribe))
            # ... and a recovering subscriber of what it may read asks for what it missed there
            # (the recovery query asks KEY/@adv/*/ZID/EID/**)
            ids.append(
                allow(
                    f"{name}-recover",
                    "ingress",
                    ["declare_subscriber", "query", "liveliness_query", "declare_liveliness_subscriber"],
                    tuple(f"{e}/@adv/**" for e in role.subscribe),
                )
            )
            ids.append(
                allow(
                    f"{name}-recover-announce",
                    "ingress",
                    ["liveliness_token"],
                    tuple(f"{e}/@adv/sub/**" for e in role.subscribe),
                )
            )
            ids.append(
                allow(
                    f"{name}-recovered",
                    "egress",
                    ["put", "reply", "liveliness_token", "declare_queryable"],
                    tuple(f"{e}/@adv/**" for e in role.subscribe),
                )
            )
        if role.service:
            ids.append(
                allow(
                    f"{name}-service",
                    "ingress",
                    ["liveliness_token", "declare_queryable", "reply"],
                    (f"alive/{role.service}/*", f"stats/{role.service}/*"),
                )
            )
            # queries arrive as asked, e.g. on stats/** (hri stats)
            ids.append(allow(f"{name}-stats", "egress", ["query"], ("stats/**",)))
        subjects.append({"id": f"role-{name}{tag}", "usernames": members})
        policies.append({"rules": ids, "subjects": [f"role-{name}{tag}"]})


def may_publish(sec: Secrets, user: str, key: str, prefix: str) -> bool:
    """Whether the rules let `user` put on the concrete `key` (for a clear message before a silent drop)."""
    import zenoh

    target = zenoh.KeyExpr(key)
    for role_name in sec.users.get(user, []):
        for expr in sec.roles[role_name].publish:
            if zenoh.KeyExpr(f"{sec.prefix_of(user, prefix)}/{expr}").includes(target):
                return True
    return False
