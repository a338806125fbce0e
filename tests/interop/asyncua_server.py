# An independent OPC UA server (Python asyncua) for cellwatch's
# interoperability tests: Basic256Sha256 + SignAndEncrypt only, Double tags
# under an object Plc in namespace URI, node ids s=NAME.
#
#   python asyncua_server.py PKI_DIR URI PORT NAME=VALUE...
#
# Listens on 127.0.0.1:PORT (0: a port the system picks) with the
# certificate and key it keeps in PKI_DIR (made on the first start, the same
# after a restart); prints "ready <own certificate, DER> <port>" once
# listening, "expired subscription" when one outlives its lifetime without
# publish requests (a client cut off: the server drops it). Standard input:
#   set NAME VALUE        write a tag (a Double)
#   recreate NAME VALUE   delete the tag's node and add it again, same node
#                         id, holding VALUE, telling its monitored items
#                         nothing (asyncua would send them a status change)
#   delete NAME           delete the tag's node as asyncua means to: its
#                         items' subscriptions get a StatusChangeNotification
#                         BadNodeIdUnknown, naming no item, and go on
#   add NAME VALUE        add it (back)
#   republishes           print "republishes N": the Republish requests
#                         answered so far
#   quit
# Each command done is told as "done <the command>".
import asyncio
import ipaddress
import logging
import os
import sys
from pathlib import Path

from asyncua import Server, ua
from asyncua.crypto import cert_gen
from asyncua.server import internal_session
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

APPLICATION_URI = "urn:cellwatch:test:asyncua"

republishes = 0


def count_republish():
    # Every Republish the server answers, whatever it answers.
    answer = internal_session.InternalSession.republish

    def counted(self, params):
        global republishes
        republishes += 1
        return answer(self, params)

    internal_session.InternalSession.republish = counted


def own_certificate(pki: Path):
    # Made once: a restarted server is the same server. The application URI
    # first among the alternative names, then the host names the agent may
    # reach it by.
    der, pem = pki / "server.der", pki / "server-key.pem"
    if der.exists() and pem.exists():
        return der, pem
    key = cert_gen.generate_private_key()
    cert = cert_gen.generate_self_signed_app_certificate(
        key,
        "cellwatch interop asyncua",
        {"organizationName": "cellwatch"},
        [
            x509.UniformResourceIdentifier(APPLICATION_URI),
            x509.DNSName("localhost"),
            x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
        ],
        [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
    )
    pki.mkdir(parents=True, exist_ok=True)
    der.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    pem.write_bytes(cert_gen.dump_private_key_as_pem(key))
    return der, pem


class Expiry(logging.Handler):
    # asyncua says a subscription's end only in its log.
    def emit(self, record):
        if "has expired" in record.getMessage():
            print("expired subscription", flush=True)


async def lines():
    loop = asyncio.get_running_loop()
    while True:
        line = await loop.run_in_executor(None, sys.stdin.readline)
        if not line:
            return
        yield line.strip()


async def main():
    pki, uri, port = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    logging.getLogger("asyncua.server.internal_subscription").addHandler(Expiry())
    count_republish()
    der, pem = own_certificate(pki)
    server = Server()
    await server.init()
    server.set_endpoint(f"opc.tcp://127.0.0.1:{port}/")
    server.set_server_name("cellwatch interop asyncua")
    await server.set_application_uri(APPLICATION_URI)
    server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
    await server.load_certificate(str(der))
    await server.load_private_key(str(pem))
    idx = await server.register_namespace(uri)
    plc = await server.nodes.objects.add_object(ua.NodeId("Plc", idx), "Plc")
    tags = {}

    async def add(name, value):
        node = await plc.add_variable(ua.NodeId(name, idx), name, ua.Variant(value, ua.VariantType.Double))
        tags[name] = node

    for arg in sys.argv[4:]:
        name, value = arg.split("=")
        await add(name, float(value))
    aspace = server.iserver.aspace
    async with server:
        port = server.bserver._server.sockets[0].getsockname()[1]
        print(f"ready {der} {port}", flush=True)
        async for line in lines():
            words = line.split()
            cmd, args = (words[0], words[1:]) if words else ("", [])
            if cmd == "set" and len(args) == 2 and args[0] in tags:
                await tags[args[0]].write_value(ua.Variant(float(args[1]), ua.VariantType.Double))
            elif cmd == "recreate" and len(args) == 2 and args[0] in tags:
                node = tags.pop(args[0])
                data = aspace[node.nodeid]
                # Forgotten, not told: the old items hear nothing more.
                for handle in list(data.attributes[ua.AttributeIds.Value].datachange_callbacks):
                    aspace.delete_datachange_callback(handle)
                await server.delete_nodes([node])
                await add(args[0], float(args[1]))
            elif cmd == "delete" and len(args) == 1 and args[0] in tags:
                node = tags.pop(args[0])
                # What asyncua's own delete means to do: it calls each
                # item's callback with BadNodeIdUnknown but does not await
                # it (2.1.0), so nothing would be sent.
                data = aspace[node.nodeid]
                for handle, callback in list(data.attributes[ua.AttributeIds.Value].datachange_callbacks.items()):
                    await callback(handle, None, ua.StatusCode(ua.StatusCodes.BadNodeIdUnknown))
                await server.delete_nodes([node])
            elif cmd == "add" and len(args) == 2 and args[0] not in tags:
                await add(args[0], float(args[1]))
            elif cmd == "republishes":
                print(f"republishes {republishes}", flush=True)
            elif cmd == "quit":
                # Gone as a stopped process is, its sockets closed by the
                # system: asyncua's own stop waits for every connection to
                # end, and one the client opens while it closes (an agent
                # reconnecting at once) never does.
                print(f"done {line}", flush=True)
                os._exit(0)
            print(f"done {line}", flush=True)


asyncio.run(main())
